//! ROS `octomap_msgs/Octomap` payloads against the golden files: a
//! message's `data` is the node stream of the `.bt` / `.ot` file, i.e. the
//! file's bytes after its `data` line, and reads back to the same tree.

mod common;

use octolinear::formats::ot::AnyTree;
use octolinear::formats::ros::{self, OctomapMsg};
use octolinear::formats::{bt, ot, TreeFileError};

fn body(file: &[u8]) -> &[u8] {
    let at = file.windows(6).position(|w| w == b"\ndata\n").expect("a data line") + 6;
    &file[at..]
}

fn header_line<'a>(file: &'a [u8], key: &str) -> &'a str {
    let text = std::str::from_utf8(&file[..file.len() - body(file).len()]).unwrap();
    text.lines().find_map(|l| l.strip_prefix(key)).unwrap().trim()
}

fn bt_bytes(msg: &OctomapMsg) -> Vec<u8> {
    let tree = ros::msg_to_map(msg).unwrap().into_occupancy().unwrap();
    let mut out = Vec::new();
    bt::write_const(&tree, &mut out).unwrap();
    out
}

#[test]
fn binary_messages_carry_the_bt_node_stream() {
    let g = common::golden();
    for rel in [
        "inputs/geb079.bt",
        "cases/color_syn_room_r0.1/color.bt",
        "cases/delete_syn_room_r0.1/empty.bt",
        "cases/syn_edges_r0.2_mrm1_d0_l0_def/tree.bt",
    ] {
        let file = common::read_maybe_gz(&g.root.join(rel));
        let tree = bt::read(&file[..]).unwrap();
        let msg = ros::binary_map_to_msg(&tree);
        assert!(msg.binary);
        assert_eq!(msg.resolution, tree.resolution());
        assert_eq!(msg.data, body(&file), "{rel}");
        assert_eq!(ros::binary_map_to_msg_compact(&tree).data, msg.data, "{rel}: already minimal");
        // read back: the same tree, whatever the (ignored) id
        let mut rewritten = bt_bytes(&msg);
        assert_eq!(body(&rewritten), body(&file), "{rel}");
        let color = OctomapMsg { id: "ColorOcTree".into(), ..msg.clone() };
        let back = ros::msg_to_map(&color).unwrap();
        assert_eq!(back.kind(), ot::TreeKind::ColorOcTree);
        rewritten = bt_bytes(&OctomapMsg { id: "no such type".into(), ..msg });
        assert_eq!(body(&rewritten), body(&file), "{rel}");
    }
}

#[test]
fn compact_binary_messages_equal_write_binary() {
    let g = common::golden();
    for (ot_rel, bt_rel) in [
        ("cases/syn_edges_r0.2_mrm1_d0_l0_def/tree.ot.gz", "cases/syn_edges_r0.2_mrm1_d0_l0_def/tree.bt"),
        ("cases/color_syn_room_r0.1/color.ot.gz", "cases/color_syn_room_r0.1/color.bt"),
    ] {
        let full = common::read_maybe_gz(&g.root.join(ot_rel));
        let binary = common::read_maybe_gz(&g.root.join(bt_rel));
        let tree = ot::read(&full[..]).unwrap().into_occupancy().unwrap();
        let before = ros::full_map_to_msg(&tree);
        let msg = ros::binary_map_to_msg_compact(&tree);
        assert_eq!(msg.data, body(&binary), "{bt_rel}");
        assert_eq!(msg.id, header_line(&binary, "id "));
        assert_eq!(ros::full_map_to_msg(&tree), before, "the tree is left unchanged");
    }
}

#[test]
fn full_messages_carry_the_ot_node_stream() {
    let g = common::golden();
    for rel in [
        "cases/delete_syn_room_r0.1/single_before.ot",
        "cases/delete_syn_room_r0.1/empty.ot",
        "cases/delete_syn_edges_r0.2/after_deletes.ot",
        "cases/color_syn_room_r0.1/color.ot.gz",
        "cases/stamped_syn_room_r0.1/stamped.ot.gz",
        "cases/counting_syn_edges_r0.05/counting.ot",
    ] {
        let file = common::read_maybe_gz(&g.root.join(rel));
        let tree = ot::read(&file[..]).unwrap();
        let msg = match &tree {
            AnyTree::Occupancy(t) => ros::full_map_to_msg(t),
            AnyTree::Counting(c) => ros::full_counting_map_to_msg(c),
        };
        assert!(!msg.binary);
        assert_eq!(msg.id, header_line(&file, "id "), "{rel}");
        assert_eq!(octolinear::formats::format_double(msg.resolution), header_line(&file, "res "));
        assert_eq!(msg.data, body(&file), "{rel}");
        let back = ros::msg_to_map(&msg).unwrap();
        assert_eq!(back.kind(), tree.kind());
        let again = match &back {
            AnyTree::Occupancy(t) => ros::full_map_to_msg(t),
            AnyTree::Counting(c) => ros::full_counting_map_to_msg(c),
        };
        assert_eq!(again, msg, "{rel}");
    }
}

#[test]
fn damaged_messages_are_errors() {
    let msg = |binary: bool, id: &str, resolution: f64, data: &[u8]| OctomapMsg {
        binary,
        id: id.into(),
        resolution,
        data: data.to_vec(),
    };
    let err = |m: OctomapMsg| ros::msg_to_map(&m).unwrap_err();
    assert!(matches!(err(msg(true, "OcTree", 0.0, &[])), TreeFileError::BadResolution { offset: None, .. }));
    assert!(matches!(err(msg(false, "OcTree", f64::NAN, &[])), TreeFileError::BadResolution { .. }));
    assert!(matches!(err(msg(false, "1", 0.1, &[])), TreeFileError::UnknownTreeType { offset: None, .. }));
    assert!(matches!(err(msg(true, "OcTree", 0.1, &[0xff])), TreeFileError::Truncated { offset: 0, .. }));
    assert!(matches!(err(msg(true, "OcTree", 0.1, &[0x00, 0x00, 0x00])), TreeFileError::WrongFormat { offset: 2, .. }));
    let deep: Vec<u8> = std::iter::repeat_n([0x03, 0x00], 17).flatten().collect();
    assert!(matches!(err(msg(true, "OcTree", 0.1, &deep)), TreeFileError::TooDeep { offset: 32 }));
    let ot_deep: Vec<u8> = std::iter::repeat_n([0, 0, 0, 0, 0x01], 17).flatten().collect();
    assert!(matches!(err(msg(false, "OcTree", 0.1, &ot_deep)), TreeFileError::TooDeep { offset: 80 }));
    // empty data: an empty tree of the named kind
    let empty = ros::msg_to_map(&msg(false, "OcTreeBase", 0.1, &[])).unwrap();
    assert_eq!(empty.kind(), ot::TreeKind::CountingOcTree);
    let empty = ros::msg_to_map(&msg(true, "anything", 0.1, &[])).unwrap().into_occupancy().unwrap();
    assert!(empty.is_empty());
}

//! One rule for a map's resolution ([`octolinear::key::check_resolution`]),
//! applied by every constructor and every reader: resolutions whose map
//! would have a voxel or an extent of 0 or infinity as floats are refused,
//! the usable range's ends accepted.

use octolinear::formats::{bt, ot, ros};
use octolinear::key::{check_resolution, KeyError, MAX_RESOLUTION, MIN_RESOLUTION};
use octolinear::sensor::SensorModel;
use octolinear::tiles::{TileError, TileWork, TiledMap};
use octolinear::tree::PreorderBuilder;
use octolinear::{CountingTree, NodeKind, OccupancyTree, TreeError, TreeFileError};

/// Outside the range: the values that made maps of resolution 0 or inf,
/// and the first doubles beyond each end.
const REFUSED: [f64; 6] = [1e-300, 1e300, 1e-40, 1e40, 0.0, f64::NAN];

fn refused() -> impl Iterator<Item = f64> {
    REFUSED.into_iter().chain([MIN_RESOLUTION.next_down(), MAX_RESOLUTION.next_up()])
}

fn same(a: f64, b: f64) -> bool {
    a.to_bits() == b.to_bits()
}

#[test]
fn trees_and_tile_sets_take_only_usable_resolutions() {
    for r in refused() {
        assert!(check_resolution(r).is_err(), "{r}");
        let bad = |e: TreeError| matches!(e, TreeError::BadResolution(v) if same(v, r));
        assert!(bad(OccupancyTree::new(r).unwrap_err()), "{r}");
        assert!(bad(OccupancyTree::with_kind(r, SensorModel::default(), NodeKind::Stamped).unwrap_err()));
        assert!(bad(CountingTree::new(r).unwrap_err()), "{r}");
        let mut b = PreorderBuilder::new();
        b.push(1.0, 0, 0).unwrap();
        assert!(bad(b.finish(r, SensorModel::default()).unwrap_err()), "{r}");
        let tile = |e: TileError| matches!(e, TileError::Tree(TreeError::BadResolution(v)) if same(v, r));
        assert!(tile(TiledMap::new(r, SensorModel::default(), NodeKind::Plain, 4).unwrap_err()), "{r}");
        assert!(tile(TileWork::new(r, 4).map(|_| ()).unwrap_err()), "{r}");
        let text = OccupancyTree::new(r).unwrap_err().to_string();
        assert!(text.starts_with(&format!("resolution {r:?} m is ")), "{text}");
    }
    for r in [MIN_RESOLUTION, MAX_RESOLUTION, 0.05] {
        assert_eq!(OccupancyTree::new(r).unwrap().resolution(), r);
        assert!(CountingTree::new(r).is_ok());
        assert!(TiledMap::new(r, SensorModel::default(), NodeKind::Plain, 4).is_ok());
        assert!(TileWork::new(r, 4).is_ok());
    }
}

/// A `.bt` or `.ot` whose header names an unusable resolution is refused
/// with the value and the offset of the value; so is an octomap_msgs
/// message.
#[test]
fn map_files_claiming_unusable_resolutions_are_refused_with_the_offset() {
    let tree = OccupancyTree::new(0.1).unwrap();
    let mut good = Vec::new();
    bt::write(&tree, &mut good).unwrap();
    let mut good_ot = Vec::new();
    ot::write(&tree, &mut good_ot).unwrap();
    for text in ["1e-300", "1e300", "1e-39", "2e34", "0"] {
        let value: f64 = text.parse().unwrap();
        for (file, is_ot) in [(&good, false), (&good_ot, true)] {
            let s = String::from_utf8_lossy(file).into_owned();
            let at = s.find("res 0.1\n").expect("res line") + 4;
            let mut bytes = file[..at].to_vec();
            bytes.extend_from_slice(text.as_bytes());
            bytes.extend_from_slice(&file[at + 3..]);
            let err =
                if is_ot { ot::read(&bytes[..]).map(|_| ()) } else { bt::read(&bytes[..]).map(|_| ()) }.unwrap_err();
            match err {
                TreeFileError::BadResolution { value: v, offset } => {
                    assert!(same(v, value), "{text}: {v}");
                    assert_eq!(offset, Some(at as u64), "{text}");
                }
                e => panic!("{text}: {e}"),
            }
            let msg = if is_ot { ot::read(&bytes[..]).map(|_| ()) } else { bt::read(&bytes[..]).map(|_| ()) }
                .unwrap_err()
                .to_string();
            assert!(
                msg.contains(&format!("resolution {value:?} m is ")) && msg.contains(&format!("at byte {at}")),
                "{msg}"
            );
        }
        let msg = ros::OctomapMsg { binary: true, id: "OcTree".into(), resolution: value, data: Vec::new() };
        assert!(matches!(ros::msg_to_map(&msg), Err(TreeFileError::BadResolution { offset: None, .. })), "{text}");
    }
    let mut bytes = good.clone();
    let s = String::from_utf8_lossy(&good).into_owned();
    let at = s.find("res 0.1\n").unwrap() + 4;
    bytes.splice(at..at + 3, b"1.1754943508222875e-38".iter().copied());
    assert!(matches!(bt::read(&bytes[..]), Err(TreeFileError::BadResolution { .. })));
    bytes = good.clone();
    bytes.splice(at..at + 3, b"2.350988701644575e-38".iter().copied());
    assert_eq!(bt::read(&bytes[..]).unwrap().resolution(), MIN_RESOLUTION);
}

/// A plan file naming an unusable resolution is refused at its line.
#[test]
fn plans_claiming_unusable_resolutions_are_refused() {
    let plan = TileWork::new(0.1, 2).unwrap().split(2).unwrap();
    let text = plan.to_text();
    assert!(octolinear::tiles::TilePlan::parse(&text).is_ok());
    for r in ["1e-300", "1e300", "0"] {
        let bad = text.replace("resolution 0.1\n", &format!("resolution {r}\n"));
        match octolinear::tiles::TilePlan::parse(&bad) {
            Err(TileError::Plan { line: 2, reason }) => assert!(reason.contains("resolution"), "{reason}"),
            other => panic!("{r}: {other:?}"),
        }
    }
}

#[test]
fn the_rule_names_the_value_and_the_range() {
    let e = check_resolution(1e-300).unwrap_err();
    assert_eq!(e, KeyError::BadResolution { value: 1e-300 });
    assert!(e.to_string().contains("below the smallest usable resolution 2.350988701644575e-38 m"));
    let e = check_resolution(1e300).unwrap_err().to_string();
    assert!(e.contains("above the largest usable resolution 1.0384593098099636e34 m"), "{e}");
}

//! The payload of ROS `octomap_msgs/Octomap` messages, converted as
//! `octomap_msgs/conversions.h` does (see `formats/ros.md`).
//!
//! A message carries `binary`, the tree type `id`, `resolution` and `data`;
//! `data` is exactly the node stream of a `.bt` file (`binary = true`,
//! OctoMap's `writeBinaryData`) or of an `.ot` file (`binary = false`,
//! `writeData`), without any text header. The ROS `header` (frame and stamp)
//! is the transport's business and is not modelled here.

use super::header::CountingReader;
use super::ot::{self, AnyTree, TreeKind};
use super::{bt, TreeFileError};
use crate::sensor::SensorModel;
use crate::tree::{CountingTree, NodeKind, OccupancyTree};

/// The fields of `octomap_msgs/Octomap` that describe the map (`data` is
/// `int8[]` on the wire; the bytes are the same).
#[derive(Clone, Debug, PartialEq)]
pub struct OctomapMsg {
    /// `true`: `data` is a `.bt` node stream (occupied/free bits only);
    /// `false`: an `.ot` node stream (full node values).
    pub binary: bool,
    /// OctoMap's tree type name, e.g. `OcTree` or `ColorOcTree`.
    pub id: String,
    /// Edge length of the smallest voxels, in metres.
    pub resolution: f64,
    /// The node stream, without any text header.
    pub data: Vec<u8>,
}

/// `binaryMapToMsg`: the tree as it is, leaves labelled free or occupied by
/// the occupancy threshold. Like octomap_msgs this neither converts to
/// maximum likelihood nor prunes; see [`binary_map_to_msg_compact`].
pub fn binary_map_to_msg(tree: &OccupancyTree) -> OctomapMsg {
    let mut data = Vec::new();
    bt::write_data(tree, &mut data).expect("writing to memory cannot fail");
    OctomapMsg { binary: true, id: TreeKind::of(tree.kind()).id().to_string(), resolution: tree.resolution(), data }
}

/// `toMaxLikelihood()`, `prune()`, then `binaryMapToMsg`, on a copy: the
/// smaller message octomap_msgs recommends, whose `data` is what follows
/// the header of the `.bt` file [`bt::write`] writes. `tree` is unchanged.
pub fn binary_map_to_msg_compact(tree: &OccupancyTree) -> OctomapMsg {
    let mut data = Vec::new();
    bt::write_ml_data(tree, &mut data);
    OctomapMsg { binary: true, id: TreeKind::of(tree.kind()).id().to_string(), resolution: tree.resolution(), data }
}

/// `fullMapToMsg`: every node with its log-odds (and colour), the node
/// stream of the `.ot` file [`ot::write`] writes.
pub fn full_map_to_msg(tree: &OccupancyTree) -> OctomapMsg {
    let mut data = Vec::new();
    ot::write_data(tree, &mut data).expect("writing to memory cannot fail");
    OctomapMsg { binary: false, id: TreeKind::of(tree.kind()).id().to_string(), resolution: tree.resolution(), data }
}

/// `fullMapToMsg` for a `CountingOcTree` (id `OcTreeBase`, `u32` counts).
pub fn full_counting_map_to_msg(tree: &CountingTree) -> OctomapMsg {
    let mut data = Vec::new();
    ot::write_counting_data(tree, &mut data).expect("writing to memory cannot fail");
    OctomapMsg { binary: false, id: TreeKind::CountingOcTree.id().to_string(), resolution: tree.resolution(), data }
}

/// `msgToMap`. Binary messages give a `ColorOcTree` (all nodes white) when
/// `id` is `ColorOcTree` and an `OcTree` for any other id, as
/// `binaryMsgToMap` does; full messages need an id [`TreeKind::from_id`]
/// knows. Empty `data` gives an empty tree. Unlike octomap_msgs, a
/// resolution that is not positive and finite, a stream that ends early or
/// goes below depth 16, and bytes left after the tree are errors (offsets
/// count from the start of `data`).
pub fn msg_to_map(msg: &OctomapMsg) -> Result<AnyTree, TreeFileError> {
    let resolution = msg.resolution;
    if crate::key::check_resolution(resolution).is_err() {
        return Err(TreeFileError::BadResolution { value: resolution, offset: None });
    }
    let mut r = CountingReader::new(&msg.data[..]);
    let tree = if msg.binary {
        let kind = if msg.id == TreeKind::ColorOcTree.id() { NodeKind::Color } else { NodeKind::Plain };
        if msg.data.is_empty() {
            return ot::empty(TreeKind::of(kind), resolution);
        }
        AnyTree::Occupancy(bt::read_data(&mut r, resolution, SensorModel::default(), kind, u64::MAX)?)
    } else {
        let kind = TreeKind::from_id(&msg.id)
            .ok_or_else(|| TreeFileError::UnknownTreeType { id: msg.id.clone(), offset: None })?;
        if msg.data.is_empty() {
            return ot::empty(kind, resolution);
        }
        ot::read_data(&mut r, kind, resolution, u64::MAX)?
    };
    let rest = msg.data.len() as u64 - r.offset;
    if rest > 0 {
        return Err(TreeFileError::WrongFormat {
            offset: r.offset,
            expected: "ROS Octomap message",
            reason: format!("{rest} bytes follow the tree's node stream (wrong `binary` flag or `id`?)"),
        });
    }
    Ok(tree)
}

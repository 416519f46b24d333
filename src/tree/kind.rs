//! The kinds of tree OctoMap has: what an in-memory tree's nodes carry
//! ([`NodeKind`]) and the tree types files name ([`TreeKind`]).

/// What nodes carry beyond log-odds, and the OctoMap rules that come with it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum NodeKind {
    /// `OcTree`.
    #[default]
    Plain,
    /// `ColorOcTree`: an RGB colour per node, white meaning "not set".
    /// Pruning ignores colours (a pruned node gets its children's average
    /// colour); inner colours are averaged by `update_inner_occupancy`.
    Color,
    /// `OcTreeStamped`: the time of the last update per node. Updates stamp
    /// the voxel and the inner nodes on its path; pruning needs equal stamps.
    Stamped,
}

/// OctoMap's tree types, as `.ot` and `.olm` files record them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TreeKind {
    /// `OcTree`: log-odds occupancy.
    OcTree,
    /// `OcTreeStamped`: occupancy and the time of the last update.
    OcTreeStamped,
    /// `ColorOcTree`: occupancy and an RGB colour.
    ColorOcTree,
    /// `CountingOcTree`: a hit count per node, no occupancy.
    CountingOcTree,
}

impl TreeKind {
    /// The type an `.ot` header id names; `None` for others.
    pub fn from_id(id: &str) -> Option<TreeKind> {
        match id {
            "OcTree" => Some(TreeKind::OcTree),
            "OcTreeStamped" => Some(TreeKind::OcTreeStamped),
            "ColorOcTree" => Some(TreeKind::ColorOcTree),
            // CountingOcTree does not override getTreeType()
            "OcTreeBase" => Some(TreeKind::CountingOcTree),
            _ => None,
        }
    }

    /// The id OctoMap writes in an `.ot` header for this type.
    pub fn id(self) -> &'static str {
        match self {
            TreeKind::CountingOcTree => "OcTreeBase",
            other => other.name(),
        }
    }

    /// The OctoMap class name, for messages (`.ot` headers name a counting
    /// tree `OcTreeBase`; this says `CountingOcTree`).
    pub fn name(self) -> &'static str {
        match self {
            TreeKind::OcTree => "OcTree",
            TreeKind::ColorOcTree => "ColorOcTree",
            TreeKind::OcTreeStamped => "OcTreeStamped",
            TreeKind::CountingOcTree => "CountingOcTree",
        }
    }

    /// The type of an occupancy tree whose nodes are of `kind`.
    pub fn of(kind: NodeKind) -> TreeKind {
        match kind {
            NodeKind::Plain => TreeKind::OcTree,
            NodeKind::Color => TreeKind::ColorOcTree,
            NodeKind::Stamped => TreeKind::OcTreeStamped,
        }
    }

    /// The node kind of the in-memory occupancy tree; `None` for a
    /// counting tree (a [`crate::CountingTree`]).
    pub fn node_kind(self) -> Option<NodeKind> {
        match self {
            TreeKind::OcTree => Some(NodeKind::Plain),
            TreeKind::ColorOcTree => Some(NodeKind::Color),
            TreeKind::OcTreeStamped => Some(NodeKind::Stamped),
            TreeKind::CountingOcTree => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_and_kinds_round_trip() {
        for k in [TreeKind::OcTree, TreeKind::OcTreeStamped, TreeKind::ColorOcTree, TreeKind::CountingOcTree] {
            assert_eq!(TreeKind::from_id(k.id()), Some(k));
            if let Some(n) = k.node_kind() {
                assert_eq!(TreeKind::of(n), k);
            }
        }
        assert_eq!(TreeKind::from_id("CountingOcTree"), None);
    }
}

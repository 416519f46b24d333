//! What colour (`ColorOcTree`) and stamped (`OcTreeStamped`) trees add:
//! colour setters, stamp degradation, conversion between kinds.

use super::{pack_rgb, unpack_rgb, NodeKind, OccupancyTree, PreorderBuilder, ROOT, WHITE};
use crate::key::Key;

impl OccupancyTree {
    // ----- colour trees (`ColorOcTree`) -------------------------------------

    /// Applies `f` to the colour of the node holding `key` (OctoMap's
    /// colour setters act on whatever `search` finds, a pruned coarse leaf
    /// included); returns the new colour, `None` when nothing was found.
    fn with_color(&mut self, key: Key, f: impl FnOnce(Option<[u8; 3]>, f32) -> [u8; 3]) -> Option<[u8; 3]> {
        if self.kind != NodeKind::Color {
            return None;
        }
        let (id, _, _) = self.search_id(key, 0)?;
        let a = self.arena_mut()?;
        let e = a.extra(id);
        let current = (e != WHITE).then(|| unpack_rgb(e));
        let rgb = f(current, a.value(id));
        a.set_extra(id, pack_rgb(rgb));
        Some(rgb)
    }

    /// `setNodeColor`.
    pub fn set_color(&mut self, key: Key, rgb: [u8; 3]) -> Option<[u8; 3]> {
        self.with_color(key, |_, _| rgb)
    }

    /// `averageNodeColor`: the mean of the old colour and `rgb`.
    pub fn average_color(&mut self, key: Key, rgb: [u8; 3]) -> Option<[u8; 3]> {
        self.with_color(key, |old, _| match old {
            Some(o) => [0, 1, 2].map(|i| ((u32::from(o[i]) + u32::from(rgb[i])) / 2) as u8),
            None => rgb,
        })
    }

    /// `integrateNodeColor`: the old colour weighted by the node's
    /// occupancy probability, the new one by `0.99 - p`.
    pub fn integrate_color(&mut self, key: Key, rgb: [u8; 3]) -> Option<[u8; 3]> {
        self.with_color(key, |old, value| match old {
            Some(o) => {
                let p = crate::sensor::probability(f64::from(value));
                [0, 1, 2].map(|i| (f64::from(o[i]) * p + f64::from(rgb[i]) * (0.99 - p)) as u8)
            }
            None => rgb,
        })
    }

    /// The same tree with nodes of another kind (e.g. a colour map as plain
    /// occupancy, which OctoMap cannot do): values and structure are kept,
    /// colours or stamps dropped, new extras start at the kind's default.
    pub fn converted(&self, kind: NodeKind) -> OccupancyTree {
        let mut b = PreorderBuilder::with_hint(kind, self.size);
        b.reserve(self.size);
        let keep = kind == self.kind;
        if let Some(root) = self.root() {
            let mut stack = vec![root];
            let mut index = 0;
            while let Some(n) = stack.pop() {
                let extra = keep.then(|| n.extra());
                b.push_with_extra(n.value(), extra, n.child_mask(), index).expect("a valid tree is at most 16 deep");
                index += 1;
                for rank in (0..n.child_count()).rev() {
                    stack.extend(n.nth_child(rank));
                }
            }
        }
        let mut t = b.finish(self.resolution(), self.sensor).expect("valid resolution").expect("complete");
        t.clock = self.clock;
        t
    }

    // ----- stamped trees (`OcTreeStamped`) -----------------------------------

    /// `getLastUpdateTime`: the root's stamp.
    pub fn last_update_time(&self) -> Option<u32> {
        if self.kind != NodeKind::Stamped {
            return None;
        }
        self.arena.as_ref().map(|a| a.extra(ROOT))
    }

    /// `degradeOutdatedNodes`: every occupied leaf whose stamp is more than
    /// `max_age` seconds old gets a miss (without a new stamp). Inner nodes
    /// are left as they are, as in OctoMap.
    pub fn degrade_outdated_nodes(&mut self, max_age: u32) {
        if self.kind != NodeKind::Stamped {
            return;
        }
        let now = self.clock.now();
        let sensor = self.sensor;
        let Some(a) = self.arena_mut() else { return };
        let mut stack = vec![ROOT];
        while let Some(n) = stack.pop() {
            if a.has_children(n) {
                let first = a.first_child(n);
                stack.extend((0..crate::arch::count_ones(a.mask(n))).map(|i| first + i));
            } else {
                let v = a.value(n);
                if sensor.is_occupied(v) && now.wrapping_sub(a.extra(n)) > max_age {
                    a.set_value(n, sensor.apply(v, sensor.miss));
                }
            }
        }
        self.refresh_trunks();
    }
}

/// The extra a new node of `kind` starts with; `None` for plain trees.
pub(crate) fn default_extra(kind: NodeKind) -> Option<u32> {
    match kind {
        NodeKind::Plain => None,
        NodeKind::Color => Some(WHITE),
        NodeKind::Stamped => Some(0),
    }
}

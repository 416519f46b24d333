//! Depth-first iteration in OctoMap's order (children 0..7).

use super::{leaf_index, NodeArena, NodeId, OccupancyTree, Parts, ROOT};
use crate::geometry::Point3;
use crate::key::packed::{self, child0, pack, unpack};
use crate::key::{Key, KeySpace, KEY_CENTER, TREE_DEPTH};

/// An inclusive box of keys, as OctoMap's bounding-box iterator takes it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KeyBox {
    /// Lowest key on each axis (inclusive).
    pub min: Key,
    /// Highest key on each axis (inclusive).
    pub max: Key,
}

impl KeyBox {
    /// Does the node at `key`/`depth` overlap the box? (OctoMap's test,
    /// which widens by the half-size offset on both sides.)
    #[inline]
    pub(crate) fn overlaps(&self, key: Key, depth: u8) -> bool {
        let off = (KEY_CENTER >> depth) as i32;
        (0..3).all(|i| {
            let k = i32::from(key.0[i]);
            i32::from(self.min.0[i]) <= k + off && i32::from(self.max.0[i]) >= k - off
        })
    }
}

/// One node as iteration reports it, from an in-memory tree or a mapped
/// map.
#[derive(Clone, Copy, Debug)]
pub struct NodeItem<'a> {
    /// The key OctoMap's iterator computes (centre key of the node).
    pub key: Key,
    /// Depth of the node (0 = root, 16 = voxel).
    pub depth: u8,
    /// Log-odds occupancy (a counting tree's count, as a float).
    pub value: f32,
    /// Colour (`r | g << 8 | b << 16`) or time stamp, by the tree's kind;
    /// 0 for plain trees.
    pub extra: u32,
    /// No children, or at the iteration's depth limit.
    pub is_leaf: bool,
    keys: &'a KeySpace,
}

impl<'a> NodeItem<'a> {
    #[inline]
    pub(crate) fn new(key: Key, depth: u8, value: f32, extra: u32, is_leaf: bool, keys: &'a KeySpace) -> Self {
        NodeItem { key, depth, value, extra, is_leaf, keys }
    }

    /// Edge length in metres.
    pub fn size(&self) -> f64 {
        self.keys.node_size(self.depth)
    }

    /// Centre in metres (double, as OctoMap's `getX/Y/Z`).
    pub fn center(&self) -> [f64; 3] {
        self.key.0.map(|k| self.keys.key_to_coord_at_depth(k, self.depth))
    }

    /// Centre as a float point (`getCoordinate`).
    pub fn center_point(&self) -> Point3 {
        self.keys.key_to_point_at_depth(self.key, self.depth)
    }
}

/// Iterator over nodes or leaves; see [`OccupancyTree::nodes`].
///
/// Keeps one frame per level (the parent's key, the id of its next child
/// and the children still to visit) instead of a stack of pushed children,
/// so a node costs one mask test and one key step. `fold` (and so
/// `for_each`, `sum`, `count`, ...) runs the same steps with the frames in
/// local variables, which the compiler keeps in registers.
pub struct NodeIter<'a> {
    walk: Walk<'a>,
    stack: Stack,
    root_pending: bool,
}

/// What an iteration visits; fixed when it starts.
#[derive(Clone, Copy)]
struct Walk<'a> {
    arena: Option<&'a NodeArena>,
    keys: &'a KeySpace,
    max_depth: u8,
    leaves_only: bool,
    bbx: Option<KeyBox>,
    /// Prefetch child groups: only in large arenas whose groups lie
    /// scattered (free runs left by moved groups; a compacted tree or one
    /// read from a file has none). In small or compacted trees the hardware
    /// prefetchers keep up, and the prefetches cost more than they save.
    prefetch: bool,
}

/// Where an iteration is: `frames[..len]`, frame `d` walking the children
/// of a node at depth `d`.
#[derive(Clone, Copy)]
struct Stack {
    frames: [Frame; TREE_DEPTH as usize],
    len: usize,
}

/// Arena slots above which a scattered arena is prefetched (about 4.5 MB of nodes).
const PREFETCH_MIN_SLOTS: usize = 512 << 10;

/// One level of the walk: the packed key of the node's child 0 (see
/// [`crate::key::packed`]), the id of its next child, the children left.
#[derive(Clone, Copy, Default)]
struct Frame {
    base: u64,
    next: NodeId,
    remaining: u8,
}

impl Frame {
    /// Takes the frame's next child: its id and packed key (the frame being
    /// at `depth`).
    #[inline(always)]
    fn take_child(&mut self, depth: usize) -> (NodeId, u64) {
        let pos = self.remaining.trailing_zeros() as usize;
        self.remaining &= self.remaining - 1;
        let id = self.next;
        self.next += 1;
        (id, packed::child(self.base, pos, depth as u8))
    }
}

impl<'a> NodeIter<'a> {
    pub(super) fn new(tree: &'a OccupancyTree, max_depth: u8, leaves_only: bool, bbx: Option<KeyBox>) -> Self {
        Self::over(tree.arena(), tree.key_space(), max_depth, leaves_only, bbx)
    }

    pub(super) fn over(
        arena: Option<&'a NodeArena>,
        keys: &'a KeySpace,
        max_depth: u8,
        leaves_only: bool,
        bbx: Option<KeyBox>,
    ) -> Self {
        let max_depth = if max_depth == 0 || max_depth > TREE_DEPTH { TREE_DEPTH } else { max_depth };
        // a walk over all of a small arena asks for it whole (and then needs
        // no group prefetches; a box walk may visit little of it); a large
        // scattered one is asked for group by group as it is walked
        let whole = bbx.is_none() && arena.is_some_and(|a| a.prefetch_all_if_small(max_depth == TREE_DEPTH));
        let prefetch = !whole && arena.is_some_and(|a| a.slot_count() > PREFETCH_MIN_SLOTS && a.free_slot_count() > 0);
        NodeIter {
            walk: Walk { arena, keys, max_depth, leaves_only, bbx, prefetch },
            stack: Stack { frames: [Frame::default(); TREE_DEPTH as usize], len: 0 },
            root_pending: arena.is_some(),
        }
    }

    /// The root's item, if it is to be reported, after opening its frame.
    fn start(&mut self, a: &'a NodeArena) -> Option<NodeItem<'a>> {
        self.root_pending = false;
        let mask = a.mask(ROOT);
        if mask != 0 {
            self.stack.frames[0] =
                Frame { base: child0(pack(Key::ROOT), 0), next: a.first_child(ROOT), remaining: mask };
            self.stack.len = 1;
            if self.walk.leaves_only {
                return None;
            }
        }
        Some(self.walk.item(a, ROOT, Key::ROOT, 0, mask == 0))
    }
}

impl<'a> Walk<'a> {
    #[inline(always)]
    fn item(&self, a: &NodeArena, n: NodeId, key: Key, depth: u8, is_leaf: bool) -> NodeItem<'a> {
        NodeItem { key, depth, value: a.value(n), extra: a.extra(n), is_leaf, keys: self.keys }
    }

    /// The next voxel of a frame of depth-15 children (one with children
    /// left).
    #[inline(always)]
    fn voxel(&self, p: &Parts<'_>, f: &mut Frame) -> NodeItem<'a> {
        let pos = f.remaining.trailing_zeros() as usize;
        f.remaining &= f.remaining - 1;
        let i = leaf_index(f.next);
        f.next += 1;
        NodeItem {
            key: unpack(packed::child(f.base, pos, TREE_DEPTH - 1)),
            depth: TREE_DEPTH,
            value: p.leaf_values[i],
            extra: p.leaf_extras.get(i).copied().unwrap_or(0),
            is_leaf: true,
            keys: self.keys,
        }
    }

    /// `fold` over every leaf below the frames of `st` (no box, no depth
    /// limit): the general step with the top frame in locals, leaves taken
    /// straight from their parent's mask test, and each depth-15 node's
    /// voxels in one loop without a frame.
    ///
    /// Out of line (the closure is still inlined into it): inlined into a
    /// larger caller, the side-by-side benchmark's timing loop, the walk
    /// took twice as long.
    #[inline(never)]
    fn fold_all_leaves<B>(
        &self,
        a: &NodeArena,
        mut st: Stack,
        mut acc: B,
        mut f: impl FnMut(B, NodeItem<'a>) -> B,
    ) -> B {
        let p = a.parts();
        let last = TREE_DEPTH as usize;
        // the voxels of a depth-15 frame that `next` left open
        if st.len == last {
            let fr = &mut st.frames[last - 1];
            while fr.remaining != 0 {
                acc = f(acc, self.voxel(&p, fr));
            }
            st.len -= 1;
        }
        let mut len = st.len;
        if len == 0 {
            return acc;
        }
        let mut top = st.frames[len - 1];
        loop {
            // a depth-14 frame: its children lie at depth 15, their
            // children (if any) are voxels
            if len == last - 1 {
                while top.remaining != 0 {
                    let (id, packed) = top.take_child(len - 1);
                    let mask = p.masks[id as usize];
                    if mask == 0 {
                        acc = f(acc, self.item(a, id, unpack(packed), TREE_DEPTH - 1, true));
                        continue;
                    }
                    let mut voxels = Frame {
                        base: child0(packed, TREE_DEPTH - 1),
                        next: p.first_child[id as usize],
                        remaining: mask,
                    };
                    while voxels.remaining != 0 {
                        acc = f(acc, self.voxel(&p, &mut voxels));
                    }
                }
            }
            if top.remaining == 0 {
                len -= 1;
                if len == 0 {
                    return acc;
                }
                top = st.frames[len - 1];
                continue;
            }
            // frames stop at depth 14, so the child lies above depth 15, in
            // the inner pool
            let (id, packed) = top.take_child(len - 1);
            let depth = len as u8;
            let mask = p.masks[id as usize];
            if mask == 0 {
                acc = f(acc, self.item(a, id, unpack(packed), depth, true));
                continue;
            }
            if self.prefetch {
                a.prefetch_grandchildren(id);
            }
            st.frames[len - 1] = top;
            top = Frame { base: child0(packed, depth), next: p.first_child[id as usize], remaining: mask };
            len += 1;
        }
    }

    /// The next node below the frames of `st`, if any.
    #[inline(always)]
    fn step(&self, a: &NodeArena, st: &mut Stack) -> Option<NodeItem<'a>> {
        // the children of a node at depth 15: voxels in the leaf pool, one
        // group, all leaves, taken without the mask look-up, the box test
        // (none here) and the frame bookkeeping below
        if st.len == TREE_DEPTH as usize && self.bbx.is_none() {
            let f = &mut st.frames[st.len - 1];
            if f.remaining != 0 {
                return Some(self.voxel(&a.parts(), f));
            }
        }
        while st.len > 0 {
            let parent_depth = (st.len - 1) as u8;
            let f = &mut st.frames[st.len - 1];
            if f.remaining == 0 {
                st.len -= 1;
                continue;
            }
            let pos = f.remaining.trailing_zeros() as usize;
            f.remaining &= f.remaining - 1;
            let id = f.next;
            f.next += 1;
            let packed = packed::child(f.base, pos, parent_depth);
            let key = unpack(packed);
            let depth = parent_depth + 1;
            if self.bbx.is_some_and(|b| !b.overlaps(key, depth)) {
                continue;
            }
            let mask = a.mask(id);
            let is_leaf = mask == 0 || depth >= self.max_depth;
            if !is_leaf {
                if self.prefetch {
                    a.prefetch_grandchildren(id);
                }
                st.frames[st.len] = Frame { base: child0(packed, depth), next: a.first_child(id), remaining: mask };
                st.len += 1;
                if self.leaves_only {
                    continue;
                }
            }
            return Some(self.item(a, id, key, depth, is_leaf));
        }
        None
    }
}

impl<'a> Iterator for NodeIter<'a> {
    type Item = NodeItem<'a>;

    #[inline]
    fn next(&mut self) -> Option<NodeItem<'a>> {
        let a = self.walk.arena?;
        if self.root_pending {
            if let Some(root) = self.start(a) {
                return Some(root);
            }
        }
        self.walk.step(a, &mut self.stack)
    }

    #[inline]
    fn fold<B, F: FnMut(B, Self::Item) -> B>(mut self, init: B, mut f: F) -> B {
        let Some(a) = self.walk.arena else { return init };
        let mut acc = init;
        if self.root_pending {
            if let Some(root) = self.start(a) {
                acc = f(acc, root);
            }
        }
        let (walk, mut stack) = (self.walk, self.stack);
        let p = a.parts();
        if walk.leaves_only && walk.bbx.is_none() && walk.max_depth == TREE_DEPTH {
            return walk.fold_all_leaves(a, stack, acc, f);
        }
        let last = TREE_DEPTH as usize;
        loop {
            // as the start of `Walk::step`, all of a group in one loop
            if stack.len == last && walk.bbx.is_none() {
                let fr = &mut stack.frames[last - 1];
                while fr.remaining != 0 {
                    acc = f(acc, walk.voxel(&p, fr));
                }
                stack.len -= 1;
            }
            match walk.step(a, &mut stack) {
                Some(item) => acc = f(acc, item),
                None => return acc,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::geometry::Point3;
    use crate::key::Key;
    use crate::tree::{InnerNodes, OccupancyTree};

    /// Leaves and nodes through `fold` equal those through `next`, from the
    /// start and resumed, on a pruned tree with leaves at every depth from
    /// 13 to 16 (8x8x8 and 4x4x4 blocks, whole and partial 2x2x2 groups, scattered
    /// voxels), with and without a depth limit.
    #[test]
    fn fold_equals_next_on_a_pruned_tree() {
        let mut t = OccupancyTree::new(0.1).unwrap();
        let set = |t: &mut OccupancyTree, x: u16, y: u16, z: u16| {
            t.set_value(Key([x, y, z]), 2.0, InnerNodes::Update);
        };
        for (x, y, z) in (0..512u16).map(|i| (i % 8, (i / 8) % 8, i / 64)) {
            set(&mut t, 32768 + x, 32768 + y, 32768 + z);
        }
        for i in 0..64u16 {
            set(&mut t, 32840 + (i & 3), 32840 + ((i >> 2) & 3), 32840 + (i >> 4));
        }
        for i in 0..8u16 {
            set(&mut t, 32800 + (i & 1), 32760 + ((i >> 1) & 1), 32770 + (i >> 2));
        }
        for i in 0..5u16 {
            set(&mut t, 32810 + (i & 1), 32750 + ((i >> 1) & 1), 32790 + (i >> 2));
        }
        let mut s = 7u32;
        for _ in 0..300 {
            s = s.wrapping_mul(1_103_515_245).wrapping_add(12_345);
            let r = |b: u32| 32700 + ((s >> b) % 160) as u16;
            set(&mut t, r(1), r(9), r(17));
        }
        t.prune();
        let depths: Vec<u8> = t.leaves(0).map(|l| l.depth).collect();
        for d in 13..=16 {
            assert!(depths.contains(&d), "no leaf at depth {d}");
        }
        type Items = Vec<(Key, u8, u32, bool)>;
        for (leaves, max_depth) in [(true, 0), (true, 15), (true, 13), (false, 0), (false, 14)] {
            let iter = || if leaves { t.leaves(max_depth) } else { t.nodes(max_depth) };
            let all: Items = {
                let mut it = iter();
                std::iter::from_fn(|| it.next()).map(|n| (n.key, n.depth, n.value.to_bits(), n.is_leaf)).collect()
            };
            for skip in (0..=all.len()).step_by(7).chain([all.len()]) {
                let mut it = iter();
                for _ in 0..skip {
                    it.next();
                }
                let rest = it.fold(Items::new(), |mut v, n| {
                    v.push((n.key, n.depth, n.value.to_bits(), n.is_leaf));
                    v
                });
                assert!(rest == all[skip..], "leaves {leaves}, depth {max_depth}, after {skip} items");
            }
        }
    }

    /// `fold` (used by `count`, `for_each`, `sum`, ...) continues from
    /// wherever `next` left off, for nodes and leaves alike.
    #[test]
    fn fold_resumes_where_next_stopped() {
        let mut t = OccupancyTree::new(0.5).unwrap();
        for i in 0..40 {
            let f = i as f32;
            t.update_point(Point3::new(f * 0.7 - 9.0, (f * 1.3) % 5.0, f * 0.1), i % 4 != 0, InnerNodes::Update)
                .unwrap();
        }
        for leaves in [false, true] {
            let iter = || if leaves { t.leaves(0) } else { t.nodes(0) };
            let all: Vec<_> = {
                let mut it = iter();
                std::iter::from_fn(|| it.next()).map(|n| (n.key, n.depth, n.value.to_bits())).collect()
            };
            assert!(all.len() >= 10, "{} items", all.len());
            for skip in 0..=all.len() {
                let mut it = iter();
                for _ in 0..skip {
                    it.next();
                }
                let rest = it.fold(Vec::new(), |mut v, n| {
                    v.push((n.key, n.depth, n.value.to_bits()));
                    v
                });
                assert_eq!(rest, all[skip..], "leaves {leaves}, after {skip} items");
            }
        }
    }
}

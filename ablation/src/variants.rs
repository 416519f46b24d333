//! The layouts compared with the pointer baseline.
//!
//! * [`ArenaLayout`] wraps octolinear's own [`OccupancyTree`] (the default
//!   in-memory layout: `values: Vec<f32>`, `masks: Vec<u8>`,
//!   `first_child: Vec<u32>`, child groups of exactly `popcount(mask)`
//!   slots), driven key by key through [`OccupancyTree::update`] or through
//!   the batch walk ([`TreeInternals::update_batch`], what
//!   `insert_point_cloud` uses), and optionally [`OccupancyTree::compact`]ed
//!   after the last scan.
//! * [`MappedLayout`] is the native read-only format: built as
//!   [`ArenaBatch`], written to `.olm` bytes in [`Layout::finish`] (the tree
//!   is dropped) and queried in place through a `MapView`.
//! * [`BlockTree`] keeps eight slots per inner node, one block per child
//!   array, absent children marked by a sentinel: [`Interleaved`] stores
//!   8-byte `{f32 value, u32 child_block}` slots (64-byte blocks), [`Split`]
//!   the same in two arrays (values, child indices).

use super::{Layout, MAX_DEPTH};
use octolinear::internals::TreeInternals;
use octolinear::key::Key;
use octolinear::mapped::{self, MappedMap};
use octolinear::morton::MortonCode;
use octolinear::sensor::SensorModel;
use octolinear::tree::{InnerNodes, OccupancyTree};

// ----- octolinear's arena ------------------------------------------------

/// [`OccupancyTree`] behind the [`Layout`] interface. `BATCH` applies each
/// scan's lists with [`TreeInternals::update_batch`] instead of key by key;
/// `COMPACT` calls [`OccupancyTree::compact`] in [`Layout::finish`].
#[derive(Clone, Debug)]
pub struct ArenaLayout<const BATCH: bool, const COMPACT: bool> {
    pub tree: OccupancyTree,
}

/// Key by key through `update(key, delta, InnerNodes::Update)`.
pub type ArenaPerKey = ArenaLayout<false, false>;
/// The batch walk `insert_point_cloud` uses.
pub type ArenaBatch = ArenaLayout<true, false>;
/// The batch walk, then `compact()`.
pub type ArenaCompact = ArenaLayout<true, true>;

impl<const BATCH: bool, const COMPACT: bool> Layout for ArenaLayout<BATCH, COMPACT> {
    fn new(resolution: f64, sensor: SensorModel) -> Self {
        ArenaLayout { tree: OccupancyTree::with_sensor(resolution, sensor).expect("valid resolution") }
    }

    fn apply_update(&mut self, key: Key, delta: f32, _sensor: &SensorModel) {
        self.tree.update(key, delta, InnerNodes::Update);
    }

    fn apply_scan(&mut self, free: &[Key], occupied: &[Key], sensor: &SensorModel) {
        if BATCH {
            let codes = |keys: &[Key]| -> Vec<u64> { keys.iter().map(|&k| MortonCode::encode(k).0).collect() };
            self.tree.update_batch(&codes(free), sensor.miss, InnerNodes::Update);
            self.tree.update_batch(&codes(occupied), sensor.hit, InnerNodes::Update);
        } else {
            for &k in free {
                self.tree.update(k, sensor.miss, InnerNodes::Update);
            }
            for &k in occupied {
                self.tree.update(k, sensor.hit, InnerNodes::Update);
            }
        }
    }

    fn finish(&mut self) {
        if COMPACT {
            self.tree.compact();
        }
    }

    fn search(&self, key: Key) -> Option<f32> {
        self.tree.search(key, 0).map(|f| f.value)
    }

    fn for_each_leaf<F: FnMut(Key, u8, f32)>(&self, mut f: F) {
        for n in self.tree.leaves(0) {
            f(n.key, n.depth, n.value);
        }
    }

    fn node_count(&self) -> usize {
        self.tree.size()
    }

    /// [`OccupancyTree::memory_usage`]: reserved arena capacity plus the
    /// tree object.
    fn bytes_formula(&self) -> usize {
        self.tree.memory_usage()
    }
}

// ----- the native mapped format ---------------------------------------

/// `.olm` (full variant, the writer's default rank index) held in a `Vec`
/// and queried in place. Until [`Layout::finish`] it is an [`ArenaBatch`];
/// updates after that are refused by a panic (it is read-only).
pub struct MappedLayout {
    building: Option<ArenaBatch>,
    map: Option<MappedMap<Vec<u8>>>,
}

impl MappedLayout {
    fn building(&mut self) -> &mut ArenaBatch {
        self.building.as_mut().expect("a mapped layout is read-only after finish()")
    }

    /// The mapped map (after [`Layout::finish`]).
    pub fn map(&self) -> Option<&MappedMap<Vec<u8>>> {
        self.map.as_ref()
    }
}

impl Layout for MappedLayout {
    fn new(resolution: f64, sensor: SensorModel) -> Self {
        MappedLayout { building: Some(ArenaBatch::new(resolution, sensor)), map: None }
    }

    fn apply_update(&mut self, key: Key, delta: f32, sensor: &SensorModel) {
        self.building().apply_update(key, delta, sensor);
    }

    fn apply_scan(&mut self, free: &[Key], occupied: &[Key], sensor: &SensorModel) {
        self.building().apply_scan(free, occupied, sensor);
    }

    fn finish(&mut self) {
        let Some(arena) = self.building.take() else { return };
        let mut bytes = mapped::to_bytes(&arena.tree, mapped::WriteOptions::default()).expect("writing to a Vec");
        drop(arena);
        bytes.shrink_to_fit();
        self.map = Some(MappedMap::new(bytes).expect("the writer's own output"));
    }

    fn search(&self, key: Key) -> Option<f32> {
        match (&self.map, &self.building) {
            (Some(m), _) => m.view().search(key, 0).map(|f| f.value),
            (None, Some(b)) => b.search(key),
            (None, None) => None,
        }
    }

    fn for_each_leaf<F: FnMut(Key, u8, f32)>(&self, mut f: F) {
        match (&self.map, &self.building) {
            (Some(m), _) => m.view().leaves(0).for_each(|n| f(n.key, n.depth, n.value)),
            (None, Some(b)) => b.for_each_leaf(f),
            (None, None) => {}
        }
    }

    fn node_count(&self) -> usize {
        match (&self.map, &self.building) {
            (Some(m), _) => m.view().size_counter() as usize,
            (None, Some(b)) => b.node_count(),
            (None, None) => 0,
        }
    }

    /// The `.olm` file's size once written, the arena's before.
    fn bytes_formula(&self) -> usize {
        match (&self.map, &self.building) {
            (Some(m), _) => m.bytes().len(),
            (None, Some(b)) => b.bytes_formula(),
            (None, None) => 0,
        }
    }
}

// ----- eight-slot blocks -------------------------------------------------

/// `child` of a slot that holds no node.
pub const ABSENT: u32 = u32::MAX;
/// `child` of a node without children.
pub const LEAF: u32 = u32::MAX - 1;

/// Slot storage of a [`BlockTree`]: slot `8 * b + i` is slot `i` of block
/// `b`. A slot holds a value and the index of its children's block (or
/// [`ABSENT`] / [`LEAF`]).
pub trait BlockStore: Default {
    /// Name in tables.
    const NAME: &'static str;
    /// Appends a block with every slot [`ABSENT`]; returns its index.
    fn push_block(&mut self) -> u32;
    fn value(&self, slot: u32) -> f32;
    fn set_value(&mut self, slot: u32, v: f32);
    fn child(&self, slot: u32) -> u32;
    fn set_child(&mut self, slot: u32, c: u32);
    /// Bytes reserved by the slot buffers.
    fn capacity_bytes(&self) -> usize;
}

/// 8-byte slots `{f32 value, u32 child_block}`: a 64-byte block per inner node.
#[derive(Clone, Debug, Default)]
pub struct Interleaved {
    slots: Vec<Slot>,
}

/// One slot of [`Interleaved`].
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub struct Slot {
    pub value: f32,
    pub child: u32,
}

impl BlockStore for Interleaved {
    const NAME: &'static str = "block8";

    fn push_block(&mut self) -> u32 {
        let b = self.slots.len() / 8;
        self.slots.extend([Slot { value: 0.0, child: ABSENT }; 8]);
        b as u32
    }
    #[inline(always)]
    fn value(&self, slot: u32) -> f32 {
        self.slots[slot as usize].value
    }
    #[inline(always)]
    fn set_value(&mut self, slot: u32, v: f32) {
        self.slots[slot as usize].value = v;
    }
    #[inline(always)]
    fn child(&self, slot: u32) -> u32 {
        self.slots[slot as usize].child
    }
    #[inline(always)]
    fn set_child(&mut self, slot: u32, c: u32) {
        self.slots[slot as usize].child = c;
    }
    fn capacity_bytes(&self) -> usize {
        self.slots.capacity() * std::mem::size_of::<Slot>()
    }
}

/// Eight-slot blocks with values and child indices in separate arrays.
#[derive(Clone, Debug, Default)]
pub struct Split {
    values: Vec<f32>,
    children: Vec<u32>,
}

impl BlockStore for Split {
    const NAME: &'static str = "split8";

    fn push_block(&mut self) -> u32 {
        let b = self.values.len() / 8;
        self.values.extend([0.0; 8]);
        self.children.extend([ABSENT; 8]);
        b as u32
    }
    #[inline(always)]
    fn value(&self, slot: u32) -> f32 {
        self.values[slot as usize]
    }
    #[inline(always)]
    fn set_value(&mut self, slot: u32, v: f32) {
        self.values[slot as usize] = v;
    }
    #[inline(always)]
    fn child(&self, slot: u32) -> u32 {
        self.children[slot as usize]
    }
    #[inline(always)]
    fn set_child(&mut self, slot: u32, c: u32) {
        self.children[slot as usize] = c;
    }
    fn capacity_bytes(&self) -> usize {
        self.values.capacity() * 4 + self.children.capacity() * 4
    }
}

/// Root slot (block 0 holds only the root).
const ROOT: u32 = 0;

/// An octree of eight-slot blocks: a block per inner node, freed blocks
/// reused through a free list.
#[derive(Clone, Debug)]
pub struct BlockTree<S: BlockStore> {
    store: S,
    free_blocks: Vec<u32>,
    size: usize,
}

/// Interleaved `{value, child}` slots.
pub type Block8 = BlockTree<Interleaved>;
/// Values and child indices in separate arrays.
pub type Split8 = BlockTree<Split>;

impl<S: BlockStore> BlockTree<S> {
    fn alloc_block(&mut self) -> u32 {
        match self.free_blocks.pop() {
            Some(b) => b,
            None => self.store.push_block(),
        }
    }

    fn free_block(&mut self, b: u32) {
        for i in 0..8 {
            self.store.set_child(8 * b + i, ABSENT);
        }
        self.free_blocks.push(b);
    }

    fn has_root(&self) -> bool {
        self.store.child(ROOT) != ABSENT
    }

    /// Eight existing childless children with equal values.
    #[inline]
    fn prunable(&self, block: u32) -> Option<f32> {
        let first = 8 * block;
        let v = self.store.value(first);
        for i in 0..8 {
            if self.store.child(first + i) != LEAF || self.store.value(first + i) != v {
                return None;
            }
        }
        Some(v)
    }

    #[inline]
    fn max_child(&self, block: u32) -> f32 {
        let mut max = -f32::MAX;
        for i in 0..8 {
            let s = 8 * block + i;
            if self.store.child(s) != ABSENT {
                let v = self.store.value(s);
                if v > max {
                    max = v;
                }
            }
        }
        max
    }
}

impl<S: BlockStore> Layout for BlockTree<S> {
    fn new(_resolution: f64, _sensor: SensorModel) -> Self {
        let mut store = S::default();
        store.push_block(); // block 0: the root in slot 0
        BlockTree { store, free_blocks: Vec::new(), size: 0 }
    }

    fn apply_update(&mut self, key: Key, delta: f32, sensor: &SensorModel) {
        if let Some(v) = self.search(key) {
            if sensor.is_saturated(v, delta) {
                return;
            }
        }
        let mut created = false;
        if !self.has_root() {
            self.store.set_value(ROOT, 0.0);
            self.store.set_child(ROOT, LEAF);
            self.size += 1;
            created = true;
        }
        let mut path = [ROOT; MAX_DEPTH as usize];
        let mut node = ROOT;
        for depth in 0..MAX_DEPTH {
            path[depth as usize] = node;
            let pos = key.child_index(depth) as u32;
            let block = self.store.child(node);
            if block == LEAF {
                let b = self.alloc_block();
                self.store.set_child(node, b);
                if created {
                    self.store.set_value(8 * b + pos, 0.0);
                    self.store.set_child(8 * b + pos, LEAF);
                    self.size += 1;
                } else {
                    // a pruned leaf: eight children holding its value
                    let v = self.store.value(node);
                    for i in 0..8 {
                        self.store.set_value(8 * b + i, v);
                        self.store.set_child(8 * b + i, LEAF);
                    }
                    self.size += 8;
                }
                node = 8 * b + pos;
            } else {
                node = 8 * block + pos;
                if self.store.child(node) == ABSENT {
                    self.store.set_value(node, 0.0);
                    self.store.set_child(node, LEAF);
                    self.size += 1;
                    created = true;
                } else {
                    created = false;
                }
            }
        }
        let v = self.store.value(node);
        self.store.set_value(node, sensor.apply(v, delta));
        for &n in path.iter().rev() {
            let block = self.store.child(n);
            if let Some(v) = self.prunable(block) {
                self.free_block(block);
                self.store.set_child(n, LEAF);
                self.store.set_value(n, v);
                self.size -= 8;
            } else {
                let m = self.max_child(block);
                self.store.set_value(n, m);
            }
        }
    }

    fn search(&self, key: Key) -> Option<f32> {
        if !self.has_root() {
            return None;
        }
        let mut node = ROOT;
        for depth in 0..MAX_DEPTH {
            let block = self.store.child(node);
            if block == LEAF {
                return Some(self.store.value(node));
            }
            node = 8 * block + key.child_index(depth) as u32;
            if self.store.child(node) == ABSENT {
                return None;
            }
        }
        Some(self.store.value(node))
    }

    fn for_each_leaf<F: FnMut(Key, u8, f32)>(&self, mut f: F) {
        if !self.has_root() {
            return;
        }
        let mut stack = vec![(ROOT, Key::ROOT, 0u8)];
        while let Some((n, key, depth)) = stack.pop() {
            let block = self.store.child(n);
            if block == LEAF || depth >= MAX_DEPTH {
                f(key, depth, self.store.value(n));
                continue;
            }
            for pos in (0..8u32).rev() {
                let c = 8 * block + pos;
                if self.store.child(c) != ABSENT {
                    stack.push((c, super::child_key(key, pos as usize, depth), depth + 1));
                }
            }
        }
    }

    fn node_count(&self) -> usize {
        self.size
    }

    /// Slot buffers' capacity plus the free list.
    fn bytes_formula(&self) -> usize {
        self.store.capacity_bytes() + self.free_blocks.capacity() * 4 + std::mem::size_of::<Self>()
    }
}

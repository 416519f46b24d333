//! The paper's pointer layout, faithfully: one heap allocation per node and
//! one per child array, as OctoMap's `OcTreeDataNode<float>` does it.
//!
//! A [`Node`] is a `float` plus a pointer to a lazily allocated array of
//! eight child pointers (`Option<Box<[Option<Box<Node>>; 8]>>`, one machine
//! pointer thanks to the null niche): 16 B on x86-64 with padding, and the
//! array 64 B, exactly the sizes of OctoMap's `OcTreeNode` and its
//! `AbstractOcTreeNode** children`. It exists to be measured, not used.

use super::{Layout, MAX_DEPTH};
use octolinear::key::Key;
use octolinear::sensor::SensorModel;

/// Eight child slots; `None` is a null pointer.
pub type Children = [Option<Box<Node>>; 8];

/// One voxel: its log-odds and its children, if any.
#[derive(Debug)]
pub struct Node {
    pub value: f32,
    pub children: Option<Box<Children>>,
}

impl Node {
    fn leaf(value: f32) -> Box<Node> {
        Box::new(Node { value, children: None })
    }

    /// OctoMap's `nodeHasChildren`: an allocated array with a non-null slot.
    #[inline]
    fn has_children(&self) -> bool {
        self.children.as_ref().is_some_and(|c| c.iter().any(Option::is_some))
    }
}

/// The pointer tree. `size` is OctoMap's maintained node counter.
#[derive(Debug)]
pub struct PointerTree {
    root: Option<Box<Node>>,
    size: usize,
    prune: bool,
}

impl PointerTree {
    /// A tree that never prunes (the paper's "no compression" octree):
    /// every voxel ever updated stays a node.
    pub fn without_pruning() -> Self {
        PointerTree { root: None, size: 0, prune: false }
    }

    /// Inner nodes and leaves, counted by a walk.
    pub fn count_inner_and_leaves(&self) -> (usize, usize) {
        fn walk(n: &Node, acc: &mut (usize, usize)) {
            match &n.children {
                Some(ch) if n.has_children() => {
                    acc.0 += 1;
                    for c in ch.iter().flatten() {
                        walk(c, acc);
                    }
                }
                _ => acc.1 += 1,
            }
        }
        let mut acc = (0, 0);
        if let Some(r) = &self.root {
            walk(r, &mut acc);
        }
        acc
    }
}

/// What one update carries down the recursion.
struct Update<'a> {
    key: Key,
    delta: f32,
    sensor: &'a SensorModel,
    prune: bool,
    size: &'a mut usize,
}

/// `updateNodeRecurs`: descend (creating or expanding), update the voxel,
/// then prune or take the children's maximum on the way back up.
fn update_recurs(node: &mut Node, node_just_created: bool, depth: u8, u: &mut Update<'_>) {
    if depth == MAX_DEPTH {
        node.value = u.sensor.apply(node.value, u.delta);
        return;
    }
    let pos = u.key.child_index(depth);
    let exists = node.children.as_ref().is_some_and(|c| c[pos].is_some());
    let mut created = false;
    if !exists {
        if !node.has_children() && !node_just_created {
            // a pruned leaf: expand into eight children holding its value
            let v = node.value;
            node.children = Some(Box::new(std::array::from_fn(|_| Some(Node::leaf(v)))));
            *u.size += 8;
        } else {
            let ch = node.children.get_or_insert_with(Box::default);
            ch[pos] = Some(Node::leaf(0.0));
            *u.size += 1;
            created = true;
        }
    }
    let child = node.children.as_mut().and_then(|c| c[pos].as_mut()).expect("child exists");
    update_recurs(child, created, depth + 1, u);

    if u.prune && prunable(node) {
        let ch = node.children.take().expect("prunable node has children");
        node.value = ch[0].as_ref().expect("all children").value;
        *u.size -= 8;
    } else {
        node.value = max_child(node);
    }
}

/// `isNodeCollapsible`: eight existing childless children with equal values.
#[inline]
fn prunable(node: &Node) -> bool {
    let Some(ch) = &node.children else { return false };
    let Some(first) = &ch[0] else { return false };
    let v = first.value;
    ch.iter().all(|c| c.as_ref().is_some_and(|c| !c.has_children() && c.value == v))
}

/// `getMaxChildLogOdds`.
#[inline]
fn max_child(node: &Node) -> f32 {
    let mut max = -f32::MAX;
    if let Some(ch) = &node.children {
        for c in ch.iter().flatten() {
            if c.value > max {
                max = c.value;
            }
        }
    }
    max
}

impl Layout for PointerTree {
    fn new(_resolution: f64, _sensor: SensorModel) -> Self {
        PointerTree { root: None, size: 0, prune: true }
    }

    fn apply_update(&mut self, key: Key, delta: f32, sensor: &SensorModel) {
        if let Some(v) = self.search(key) {
            if sensor.is_saturated(v, delta) {
                return;
            }
        }
        let created = self.root.is_none();
        if created {
            self.size += 1;
        }
        let root = self.root.get_or_insert_with(|| Node::leaf(0.0));
        let mut u = Update { key, delta, sensor, prune: self.prune, size: &mut self.size };
        update_recurs(root, created, 0, &mut u);
    }

    fn search(&self, key: Key) -> Option<f32> {
        let mut node = self.root.as_deref()?;
        for depth in 0..MAX_DEPTH {
            match &node.children {
                Some(ch) => match &ch[key.child_index(depth)] {
                    Some(c) => node = c,
                    None if node.has_children() => return None,
                    None => return Some(node.value),
                },
                None => return Some(node.value),
            }
        }
        Some(node.value)
    }

    fn for_each_leaf<F: FnMut(Key, u8, f32)>(&self, mut f: F) {
        fn walk<F: FnMut(Key, u8, f32)>(n: &Node, key: Key, depth: u8, f: &mut F) {
            match &n.children {
                Some(ch) if depth < MAX_DEPTH && n.has_children() => {
                    for (pos, c) in ch.iter().enumerate() {
                        if let Some(c) = c {
                            walk(c, super::child_key(key, pos, depth), depth + 1, f);
                        }
                    }
                }
                _ => f(key, depth, n.value),
            }
        }
        if let Some(r) = &self.root {
            walk(r, Key::ROOT, 0, &mut f);
        }
    }

    fn node_count(&self) -> usize {
        self.size
    }

    /// `16 * nodes + 64 * inner nodes`: one `Node` box per node, one child
    /// array per inner node (what the allocator sees, before malloc's own
    /// per-chunk overhead).
    fn bytes_formula(&self) -> usize {
        let (inner, leaves) = self.count_inner_and_leaves();
        std::mem::size_of::<Node>() * (inner + leaves) + std::mem::size_of::<Children>() * inner
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn node_sizes_are_the_papers_64_bit_sizes() {
        assert_eq!(std::mem::size_of::<Node>(), 16);
        assert_eq!(std::mem::size_of::<Children>(), 64);
        assert_eq!(std::mem::size_of::<Option<Box<Node>>>(), 8);
    }
}

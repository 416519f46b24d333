//! [`Parts`]: the raw arrays of both pools, the read-only view tree walks
//! and the file formats read.

use super::{in_leaf_pool, leaf_index, prefetch, NodeId};

/// The arrays of both pools, for read-only passes over the whole tree.
/// Inner-pool ids index the first four, leaf-pool ids (less [`LEAF_POOL`])
/// the last two; the extras are empty when extras are off.
#[derive(Clone, Copy)]
pub(crate) struct Parts<'a> {
    pub values: &'a [f32],
    pub masks: &'a [u8],
    pub first_child: &'a [NodeId],
    pub extras: &'a [u32],
    pub leaf_values: &'a [f32],
    pub leaf_extras: &'a [u32],
}

impl Parts<'_> {
    /// The arrays of no node.
    pub const EMPTY: Self =
        Parts { values: &[], masks: &[], first_child: &[], extras: &[], leaf_values: &[], leaf_extras: &[] };

    /// The value of any node.
    #[inline(always)]
    pub fn value(&self, n: NodeId) -> f32 {
        if in_leaf_pool(n) {
            self.leaf_values[leaf_index(n)]
        } else {
            self.values[n as usize]
        }
    }

    /// The extra of any node (0 when extras are off).
    #[inline(always)]
    pub fn extra(&self, n: NodeId) -> u32 {
        let e = if in_leaf_pool(n) { self.leaf_extras.get(leaf_index(n)) } else { self.extras.get(n as usize) };
        e.copied().unwrap_or(0)
    }

    /// The child mask of any node (0 in the leaf pool).
    #[inline(always)]
    pub fn mask(&self, n: NodeId) -> u8 {
        if in_leaf_pool(n) {
            0
        } else {
            self.masks[n as usize]
        }
    }

    /// One step of a descent: child `pos` of `n`, which lies above depth
    /// 16 (so in the inner pool, indexed without the pool check), or
    /// `Err(mask of n)` when that child does not exist.
    #[inline(always)]
    pub fn descend(&self, n: NodeId, pos: u64) -> Result<NodeId, u8> {
        let m = self.masks[n as usize];
        if m & (1 << pos) == 0 {
            Err(m)
        } else {
            Ok(self.first_child[n as usize] + crate::arch::count_ones(u32::from(m) & ((1 << pos) - 1)))
        }
    }

    /// Asks for the cache lines of the group starting at `first`.
    #[inline(always)]
    pub fn prefetch_group(&self, first: NodeId) {
        if in_leaf_pool(first) {
            prefetch(self.leaf_values, leaf_index(first));
            prefetch(self.leaf_extras, leaf_index(first));
        } else {
            let i = first as usize;
            prefetch(self.masks, i);
            prefetch(self.values, i);
            prefetch(self.first_child, i);
            prefetch(self.extras, i);
        }
    }
}

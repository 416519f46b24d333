//! Change detection: which voxels were created or flipped occupancy.

use super::OccupancyTree;
use crate::key::Key;
use hashbrown::HashMap;

impl OccupancyTree {
    /// Starts (or stops) recording which voxels changed occupancy.
    pub fn set_change_detection(&mut self, enabled: bool) {
        if enabled {
            self.changes.get_or_insert_with(HashMap::new);
        } else {
            self.changes = None;
        }
    }

    /// Keys changed since the last reset: `true` for newly created voxels,
    /// `false` for existing voxels whose occupancy state flipped. Sorted.
    pub fn changed_keys(&self) -> Vec<(Key, bool)> {
        let mut v: Vec<_> = self.changes.iter().flat_map(|c| c.iter().map(|(k, b)| (*k, *b))).collect();
        v.sort_unstable();
        v
    }

    /// Forgets the changed keys recorded so far (`resetChangeDetection`).
    pub fn reset_change_detection(&mut self) {
        if let Some(c) = self.changes.as_mut() {
            c.clear();
        }
    }
}

/// Records that the voxel at `key` was updated: `created`, or its
/// occupancy went from `was` to `is` (`changedKeys`' bookkeeping: a flip
/// back removes the entry; a created voxel stays created).
#[inline]
pub(super) fn record_change(changes: &mut HashMap<Key, bool>, key: Key, created: bool, was: bool, is: bool) {
    if created {
        changes.insert(key, true);
    } else if was != is {
        match changes.get(&key) {
            None => {
                changes.insert(key, false);
            }
            Some(false) => {
                changes.remove(&key);
            }
            Some(true) => {}
        }
    }
}

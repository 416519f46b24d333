//! OctoMap's per-node rules on any node store: pruning eight equal
//! children, inner values from the children, colour averaging.

use super::arena::NodeStore;
use super::{pack_rgb, unpack_rgb, NodeId, NodeKind, Rules, WHITE};

/// `getMaxChildLogOdds`.
#[inline]
fn max_child_value<S: NodeStore>(a: &S, n: NodeId) -> f32 {
    let first = a.first_child(n);
    let mut max = -f32::MAX;
    for i in 0..crate::arch::count_ones(a.mask(n)) {
        let v = a.value(first + i);
        if v > max {
            max = v;
        }
    }
    max
}

/// `pruneNode`: merges eight equal childless children into `n` (which
/// takes child 0's data); returns the value. Stamped trees also need equal
/// stamps; colour trees ignore colours and give the merged node the average.
#[inline]
pub(super) fn prune_node<S: NodeStore>(a: &mut S, n: NodeId, rules: Rules) -> Option<f32> {
    if a.mask(n) != 0xff {
        return None;
    }
    let first = a.first_child(n);
    let v = a.value(first);
    let e = a.extra(first);
    for i in 0..8 {
        let c = first + i;
        if a.has_children(c) || a.value(c) != v {
            return None;
        }
        if rules.kind == NodeKind::Stamped && a.extra(c) != e {
            return None;
        }
    }
    let extra = if rules.kind == NodeKind::Color && e != WHITE { average_child_color(a, n) } else { e };
    a.remove_all_children(n);
    a.set_value(n, v);
    a.set_extra(n, extra);
    Some(v)
}

/// [`prune_node`], else [`update_from_children`], for plain trees in one
/// pass over the children; returns whether `n` was pruned.
#[inline]
pub(super) fn prune_or_update_plain<S: NodeStore>(a: &mut S, n: NodeId) -> bool {
    let mask = a.mask(n);
    let first = a.first_child(n);
    let v0 = a.value(first);
    let mut max = -f32::MAX;
    let mut same = mask == 0xff;
    for i in 0..crate::arch::count_ones(mask) {
        let c = first + i;
        let v = a.value(c);
        if v > max {
            max = v;
        }
        same &= (v == v0) & !a.has_children(c);
    }
    if same {
        a.remove_all_children(n);
        a.set_value(n, v0);
    } else {
        a.set_value(n, max);
    }
    same
}

/// `updateOccupancyChildren`: the maximum of the children's values (and,
/// for stamped trees, the current time).
#[inline]
pub(super) fn update_from_children<S: NodeStore>(a: &mut S, n: NodeId, rules: Rules) {
    let v = max_child_value(a, n);
    a.set_value(n, v);
    if rules.kind == NodeKind::Stamped {
        a.set_extra(n, rules.now);
    }
}

/// `getAverageChildColor`: integer mean over children whose colour is set,
/// white when none is.
pub(super) fn average_child_color<S: NodeStore>(a: &S, n: NodeId) -> u32 {
    let (mut sum, mut count) = ([0u32; 3], 0u32);
    let first = a.first_child(n);
    for c in first..first + crate::arch::count_ones(a.mask(n)) {
        let e = a.extra(c);
        if e != WHITE {
            let rgb = unpack_rgb(e);
            for k in 0..3 {
                sum[k] += u32::from(rgb[k]);
            }
            count += 1;
        }
    }
    if count == 0 {
        return WHITE;
    }
    pack_rgb([(sum[0] / count) as u8, (sum[1] / count) as u8, (sum[2] / count) as u8])
}

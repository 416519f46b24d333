//! The log-odds sensor model, computed in OctoMap's float arithmetic.

/// `octomap::logodds`: computed in double, stored as float.
pub fn logodds(probability: f64) -> f32 {
    (probability / (1.0 - probability)).ln() as f32
}

/// `octomap::probability`: the inverse of [`logodds`], in double.
pub fn probability(logodds: f64) -> f64 {
    1.0 - (1.0 / (1.0 + logodds.exp()))
}

/// Why a sensor model was refused.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum SensorError {
    /// A value is not strictly between 0 and 1 (or is NaN).
    #[error("{name} = {value} is not a probability strictly between 0 and 1")]
    NotAProbability {
        /// Which value: `prob_hit`, `prob_miss`, `clamping_min`, `clamping_max` or `occupancy_threshold`.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// The hit probability (the value given) is below 0.5.
    #[error("prob_hit = {0} must be at least 0.5 (a hit must not lower occupancy)")]
    HitBelowHalf(f64),
    /// The miss probability (the value given) is above 0.5.
    #[error("prob_miss = {0} must be at most 0.5 (a miss must not raise occupancy)")]
    MissAboveHalf(f64),
    /// The lower clamping bound is not below the upper one.
    #[error("clamping min {min} must be below clamping max {max}")]
    ClampingOrder {
        /// The lower clamping probability given.
        min: f64,
        /// The upper clamping probability given.
        max: f64,
    },
}

/// Probabilities describing a sensor, as a user states them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorProbabilities {
    /// Probability a hit (a ray's end point) assigns to its voxel, OctoMap's `prob_hit`.
    pub hit: f64,
    /// Probability a miss (a voxel a ray passes through) assigns, OctoMap's `prob_miss`.
    pub miss: f64,
    /// Lower bound occupancy is clamped to, OctoMap's `clamping_thres_min`.
    pub clamping_min: f64,
    /// Upper bound occupancy is clamped to, OctoMap's `clamping_thres_max`.
    pub clamping_max: f64,
    /// Occupancy at or above which a voxel counts as occupied, OctoMap's `occupancy_thres`.
    pub occupancy_threshold: f64,
}

impl Default for SensorProbabilities {
    /// OctoMap's defaults.
    fn default() -> Self {
        SensorProbabilities { hit: 0.7, miss: 0.4, clamping_min: 0.1192, clamping_max: 0.971, occupancy_threshold: 0.5 }
    }
}

/// The log-odds values a tree works with (all `f32`, as OctoMap stores them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorModel {
    /// Log-odds added for a hit, OctoMap's `prob_hit_log`.
    pub hit: f32,
    /// Log-odds added for a miss (negative), OctoMap's `prob_miss_log`.
    pub miss: f32,
    /// Lower clamping bound in log-odds, OctoMap's `clamping_thres_min`.
    pub clamping_min: f32,
    /// Upper clamping bound in log-odds, OctoMap's `clamping_thres_max`.
    pub clamping_max: f32,
    /// Occupancy threshold in log-odds, OctoMap's `occ_prob_thres_log`.
    pub occupancy_threshold: f32,
}

impl Default for SensorModel {
    fn default() -> Self {
        SensorModel::from_probabilities(&SensorProbabilities::default()).expect("OctoMap's defaults are valid")
    }
}

impl SensorModel {
    /// Converts probabilities to log-odds as OctoMap's setters do.
    pub fn from_probabilities(p: &SensorProbabilities) -> Result<Self, SensorError> {
        for (name, value) in [
            ("prob_hit", p.hit),
            ("prob_miss", p.miss),
            ("clamping_min", p.clamping_min),
            ("clamping_max", p.clamping_max),
            ("occupancy_threshold", p.occupancy_threshold),
        ] {
            if !(value > 0.0 && value < 1.0) {
                return Err(SensorError::NotAProbability { name, value });
            }
        }
        if p.hit < 0.5 {
            return Err(SensorError::HitBelowHalf(p.hit));
        }
        if p.miss > 0.5 {
            return Err(SensorError::MissAboveHalf(p.miss));
        }
        if p.clamping_min >= p.clamping_max {
            return Err(SensorError::ClampingOrder { min: p.clamping_min, max: p.clamping_max });
        }
        Ok(SensorModel {
            hit: logodds(p.hit),
            miss: logodds(p.miss),
            clamping_min: logodds(p.clamping_min),
            clamping_max: logodds(p.clamping_max),
            occupancy_threshold: logodds(p.occupancy_threshold),
        })
    }

    /// The probabilities OctoMap's getters report (`probability(logodds)`).
    pub fn probabilities(&self) -> SensorProbabilities {
        SensorProbabilities {
            hit: probability(f64::from(self.hit)),
            miss: probability(f64::from(self.miss)),
            clamping_min: probability(f64::from(self.clamping_min)),
            clamping_max: probability(f64::from(self.clamping_max)),
            occupancy_threshold: probability(f64::from(self.occupancy_threshold)),
        }
    }

    /// `updateNodeLogOdds`: add in float, then clamp.
    #[inline(always)]
    pub fn apply(&self, value: f32, delta: f32) -> f32 {
        let v = value + delta;
        if v < self.clamping_min {
            self.clamping_min
        } else if v > self.clamping_max {
            self.clamping_max
        } else {
            v
        }
    }

    /// `setNodeValue`'s clamping: `std::min(std::max(v, min), max)`.
    #[inline]
    pub fn clamp(&self, value: f32) -> f32 {
        let v = if value < self.clamping_min { self.clamping_min } else { value };
        if self.clamping_max < v {
            self.clamping_max
        } else {
            v
        }
    }

    /// `isNodeOccupied`: the log-odds value is at or above the occupancy threshold.
    #[inline(always)]
    pub fn is_occupied(&self, value: f32) -> bool {
        value >= self.occupancy_threshold
    }

    /// `isNodeAtThreshold`: the value sits at a clamping bound.
    #[inline]
    pub fn is_at_threshold(&self, value: f32) -> bool {
        value >= self.clamping_max || value <= self.clamping_min
    }

    /// `nodeToMaxLikelihood`.
    #[inline]
    pub fn max_likelihood(&self, value: f32) -> f32 {
        if self.is_occupied(value) {
            self.clamping_max
        } else {
            self.clamping_min
        }
    }

    /// `updateNode`'s early exit: the update cannot change a node at a bound.
    #[inline(always)]
    pub fn is_saturated(&self, value: f32, delta: f32) -> bool {
        (delta >= 0.0 && value >= self.clamping_max) || (delta <= 0.0 && value <= self.clamping_min)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_have_octomaps_bits() {
        let m = SensorModel::default();
        assert_eq!(m.hit.to_bits(), 0x3f58e883);
        assert_eq!(m.miss.to_bits(), 0xbecf991f);
        assert_eq!(m.clamping_min.to_bits(), 0xc0000075);
        assert_eq!(m.clamping_max.to_bits(), 0x4060b4ba);
        assert_eq!(m.occupancy_threshold.to_bits(), 0);
    }

    #[test]
    fn rejects_nonsense() {
        let mut p = SensorProbabilities { hit: f64::NAN, ..Default::default() };
        assert!(SensorModel::from_probabilities(&p).is_err());
        p.hit = 0.3;
        assert_eq!(SensorModel::from_probabilities(&p), Err(SensorError::HitBelowHalf(0.3)));
        p = SensorProbabilities { clamping_min: 0.9, clamping_max: 0.2, ..Default::default() };
        assert!(SensorModel::from_probabilities(&p).is_err());
    }
}

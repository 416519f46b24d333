//! BMI2, detected at run time: Morton codes by `pdep` and `pext`, one
//! instruction per axis (the `morton` benchmarks compare them with the
//! shift-and-mask and table encoders).

use crate::key::Key;
use crate::morton::MortonCode;
use std::arch::x86_64::{_pdep_u64, _pext_u64};

/// The x bits of a Morton code (y and z: shifted by one and two).
const MASK_X: u64 = 0x2492_4924_9249;

/// Proof that the processor has BMI2: only [`Bmi2::detect`] makes one.
#[derive(Clone, Copy)]
pub(crate) struct Bmi2(());

impl Bmi2 {
    /// `Some` when the processor has BMI2 (the detection is cached by the
    /// standard library: a load and a test).
    #[inline]
    pub(crate) fn detect() -> Option<Self> {
        std::arch::is_x86_feature_detected!("bmi2").then_some(Bmi2(()))
    }

    /// [`MortonCode::encode`] by `pdep`.
    #[inline]
    pub(crate) fn morton_encode(self, key: Key) -> MortonCode {
        // SAFETY: a `Bmi2` exists only on a processor with BMI2.
        unsafe { encode(key) }
    }

    /// [`MortonCode::decode`] by `pext`.
    #[inline]
    pub(crate) fn morton_decode(self, code: MortonCode) -> Key {
        // SAFETY: a `Bmi2` exists only on a processor with BMI2.
        unsafe { decode(code) }
    }
}

#[target_feature(enable = "bmi2")]
fn encode(key: Key) -> MortonCode {
    let [x, y, z] = key.0;
    MortonCode(
        _pdep_u64(u64::from(x), MASK_X) | _pdep_u64(u64::from(y), MASK_X << 1) | _pdep_u64(u64::from(z), MASK_X << 2),
    )
}

#[target_feature(enable = "bmi2")]
fn decode(code: MortonCode) -> Key {
    Key([
        _pext_u64(code.0, MASK_X) as u16,
        _pext_u64(code.0, MASK_X << 1) as u16,
        _pext_u64(code.0, MASK_X << 2) as u16,
    ])
}

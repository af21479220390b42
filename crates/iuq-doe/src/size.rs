//! The size limit shared by all designs.
//!
//! A design is held in memory as `n` rows of `dim` values; a request beyond any realistic size
//! (e.g. a mistyped `n`) must be reported as an error, not abort the process on a failed
//! allocation or panic on a capacity overflow.

use crate::error::{DoeError, Result};

/// Most values (`n · dim`, or `N(d + 2) · d` for a Saltelli design) a design may hold: `2^28`
/// (2 GiB of `f64`, more with the per-row overhead of `Vec<Vec<f64>>`; a Saltelli design with
/// `N = 2^14` and `d = 100` holds 1.7·10^8).
pub const MAX_DESIGN_VALUES: usize = 1 << 28;

/// Checks `n ≥ 1`, `dim ≥ 1` and `n · dim ≤ MAX_DESIGN_VALUES` (`what` names the design in the
/// messages).
pub(crate) fn check_size(n: usize, dim: usize, what: &str) -> Result<()> {
    if n == 0 {
        return Err(DoeError::InvalidSampleSize {
            n,
            reason: format!("a {what} needs at least one point"),
        });
    }
    if dim == 0 {
        return Err(DoeError::InvalidDimension {
            dim,
            reason: format!("a {what} needs at least one coordinate"),
        });
    }
    if n.checked_mul(dim).is_none_or(|v| v > MAX_DESIGN_VALUES) {
        return Err(DoeError::InvalidSampleSize {
            n,
            reason: format!(
                "{n} points of {dim} coordinates exceed the limit of {MAX_DESIGN_VALUES} values"
            ),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits() {
        assert!(check_size(10, 3, "design").is_ok());
        assert!(check_size(0, 3, "design").is_err());
        assert!(check_size(10, 0, "design").is_err());
        assert!(check_size(usize::MAX, 2, "design").is_err());
        assert!(check_size(MAX_DESIGN_VALUES, 1, "design").is_ok());
        assert!(check_size(MAX_DESIGN_VALUES, 2, "design").is_err());
    }
}

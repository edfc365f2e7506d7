//! Numbers in messages, written compactly: `1e-300` rather than a decimal point followed by
//! 299 zeros, `1e308` rather than 309 digits. Rust's `{}` for `f64` never uses an exponent,
//! which makes an error about a tolerance of 1e-300 unreadable.

use core::fmt;

/// `x` for a message: plain decimal between 1e-4 and 1e15 in magnitude (and 0), scientific
/// notation otherwise; both are the shortest text that reads back as `x`.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct Compact(pub f64);

impl fmt::Display for Compact {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let x = self.0;
        let magnitude = x.abs();
        if !x.is_finite() || x == 0.0 || (1e-4..1e15).contains(&magnitude) {
            write!(f, "{x}")
        } else {
            write!(f, "{x:e}")
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Compact;

    #[test]
    fn extreme_numbers_are_short_and_read_back() {
        for x in [1e-300, 1e-16, 1e308, 5e-324, -2.5e-7, 1.7976931348623157e308, 0.1, 1e-4, 123.25, 1e14, 0.0, -0.0] {
            let s = Compact(x).to_string();
            assert!(s.len() <= 24, "{s}");
            assert_eq!(s.parse::<f64>().unwrap().to_bits(), x.to_bits(), "{s}");
        }
        assert_eq!(Compact(1e-300).to_string(), "1e-300");
        assert_eq!(Compact(0.5).to_string(), "0.5");
        assert_eq!(Compact(f64::INFINITY).to_string(), "inf");
    }
}

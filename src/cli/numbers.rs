//! Range-checked parsers for every number the command line takes: a value out of range is
//! a clap error naming the flag and the range, never a panic later (`Duration` from a
//! negative, NaN or 1e300 s) nor a loop that never ends.

/// A number the command line cannot take, and why (clap prints it beside the flag).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct BadNumber(pub String);

/// A finite number in `lo..=hi`, or the error clap prints beside the flag.
fn in_range(s: &str, lo: f64, hi: f64, what: &str) -> Result<f64, BadNumber> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| BadNumber(format!("`{s}` is not a number")))?;
    if !(v.is_finite() && v >= lo && v <= hi) {
        return Err(BadNumber(format!(
            "{what} must be between {lo} and {hi}, got {s}"
        )));
    }
    Ok(v)
}

/// Seconds from 0 to a day (a duration, a start delay).
pub fn seconds(s: &str) -> Result<f64, BadNumber> {
    in_range(s, 0.0, 86_400.0, "seconds")
}

/// A timeout: more than 0 and at most an hour, s.
pub fn timeout_seconds(s: &str) -> Result<f64, BadNumber> {
    let v = in_range(s, 0.0, 3_600.0, "a timeout in seconds")?;
    if v == 0.0 {
        return Err(BadNumber("a timeout must be more than 0 s".into()));
    }
    Ok(v)
}

/// A share, percent, 0-100.
pub fn percent(s: &str) -> Result<f64, BadNumber> {
    in_range(s, 0.0, 100.0, "a percentage")
}

/// A latency, 0-60,000 ms.
pub fn millis(s: &str) -> Result<f64, BadNumber> {
    in_range(s, 0.0, 60_000.0, "milliseconds")
}

/// A count from 1 to `hi`.
fn count(s: &str, hi: u64) -> Result<u64, BadNumber> {
    let v: u64 = s
        .trim()
        .parse()
        .map_err(|_| BadNumber(format!("`{s}` is not a whole number")))?;
    if !(1..=hi).contains(&v) {
        return Err(BadNumber(format!("must be between 1 and {hi}, got {v}")));
    }
    Ok(v)
}

/// Monte Carlo runs, 1-100,000.
pub fn runs(s: &str) -> Result<u64, BadNumber> {
    count(s, 100_000)
}

/// Worker threads, 1-1,024.
pub fn threads(s: &str) -> Result<usize, BadNumber> {
    count(s, 1_024).map(|v| v as usize)
}

/// Repetitions of a benchmark, 1-1,000,000.
pub fn repetitions(s: &str) -> Result<usize, BadNumber> {
    count(s, 1_000_000).map(|v| v as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn out_of_range_numbers_are_errors_naming_the_range() {
        for bad in ["-1", "nan", "inf", "1e30", "x", ""] {
            assert!(timeout_seconds(bad).is_err(), "{bad}");
            assert!(
                seconds(bad).is_err() || bad == "-1" && seconds(bad).is_err(),
                "{bad}"
            );
        }
        assert!(timeout_seconds("0").is_err());
        assert_eq!(timeout_seconds("10").unwrap(), 10.0);
        assert!(percent("101").is_err());
        assert_eq!(percent("30").unwrap(), 30.0);
        assert!(millis("1e9").is_err());
        assert!(runs("0").is_err());
        assert!(runs("18446744073709551616").is_err());
        assert_eq!(threads("2").unwrap(), 2);
        assert!(repetitions("0").is_err());
    }
}

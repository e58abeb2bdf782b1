//! The range checks every component runs on its own configuration table, and the typed
//! error they return: the dotted key, the value as written and why it is refused.

/// A configuration value a component refuses.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("`{key}` = {value}: {reason}")]
pub struct InvalidValue {
    /// Dotted path of the key, e.g. `filter.particles`.
    pub key: String,
    /// The offending value as written.
    pub value: String,
    /// Why it is refused.
    pub reason: String,
}

/// The result of a component's check of its table.
pub type Checked = Result<(), InvalidValue>;

/// An [`InvalidValue`] for `key`, printing `value` as written.
pub fn invalid(key: impl Into<String>, value: impl std::fmt::Debug, reason: &str) -> InvalidValue {
    InvalidValue {
        key: key.into(),
        value: format!("{value:?}"),
        reason: reason.to_string(),
    }
}

/// A finite number greater than 0.
pub fn positive(key: &str, v: f64) -> Checked {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(key, v, "must be a finite number greater than 0"))
    }
}

/// A finite number at least 0.
pub fn non_negative(key: &str, v: f64) -> Checked {
    if v.is_finite() && v >= 0.0 {
        Ok(())
    } else {
        Err(invalid(key, v, "must be a finite number >= 0"))
    }
}

/// A share in [0, 1].
pub fn in_unit(key: &str, v: f64) -> Checked {
    if v.is_finite() && (0.0..=1.0).contains(&v) {
        Ok(())
    } else {
        Err(invalid(key, v, "must lie in [0, 1]"))
    }
}

/// A count of at least 1.
pub fn count(key: &str, v: usize) -> Checked {
    if v > 0 {
        Ok(())
    } else {
        Err(invalid(key, v, "must be at least 1"))
    }
}

/// A 2x2 covariance: symmetric positive definite.
pub fn covariance(key: &str, m: &[[f64; 2]; 2]) -> Checked {
    let finite = m.iter().flatten().all(|v| v.is_finite());
    let symmetric = (m[0][1] - m[1][0]).abs() <= 1e-12 * (1.0 + m[0][1].abs());
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    if finite && symmetric && m[0][0] > 0.0 && det > 0.0 {
        Ok(())
    } else {
        Err(invalid(
            key,
            m,
            "must be a symmetric positive-definite 2x2 matrix",
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_check_refuses_its_boundary_and_names_the_key() {
        assert_eq!(positive("a.b", 0.0).unwrap_err().key, "a.b");
        assert!(positive("a.b", f64::NAN).is_err());
        assert!(positive("a.b", 1e-9).is_ok());
        assert!(non_negative("a.b", 0.0).is_ok());
        assert!(non_negative("a.b", -1e-9).is_err());
        assert!(in_unit("a.b", 1.0).is_ok());
        assert!(in_unit("a.b", 1.0 + 1e-9).is_err());
        assert!(count("a.b", 0).is_err());
        assert!(count("a.b", 1).is_ok());
    }

    #[test]
    fn a_covariance_must_be_symmetric_positive_definite() {
        assert!(covariance("q", &[[1.0, 0.5], [0.5, 1.0]]).is_ok());
        assert!(covariance("q", &[[1.0, 0.5], [0.4, 1.0]]).is_err());
        assert!(covariance("q", &[[1.0, 2.0], [2.0, 1.0]]).is_err());
        let e = covariance("q", &[[-1.0, 0.0], [0.0, 1.0]]).unwrap_err();
        assert_eq!(
            e.to_string(),
            "`q` = [[-1.0, 0.0], [0.0, 1.0]]: must be a symmetric positive-definite 2x2 matrix"
        );
    }
}

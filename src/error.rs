//! Errors. Every validation error names the field (as a JSON path, e.g.
//! `tone_curve.y[3]`) and the rule it broke.

use thiserror::Error;

/// A value broke a rule of the parameter model or of a conversion input.
///
/// Every variant's `field` is the JSON path of the offending value (`ccm[1][2]`).
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
#[allow(missing_docs)] // the fields are the same in every variant: documented above
pub enum ValidationError {
    /// NaN or infinite.
    #[error("{field}: must be a finite number, got {value}")]
    NonFinite { field: String, value: f64 },
    /// Outside `[min, max]`.
    #[error("{field}: must be in [{min}, {max}], got {value}")]
    OutOfRange { field: String, value: f64, min: f64, max: f64 },
    /// A list of the wrong length (`expected` says what it must be).
    #[error("{field}: must have {expected} entries, got {got}")]
    WrongLength { field: String, expected: String, got: usize },
    /// Entry `index` is not larger than the one before.
    #[error("{field}: must be strictly increasing, but entry {index} ({value}) follows {prev}")]
    NotIncreasing { field: String, index: usize, prev: f64, value: f64 },
    /// An end point (first or last knot input) is not where it must be.
    #[error("{field}: must be {expected}, got {value}")]
    WrongEndpoint { field: String, expected: f64, value: f64 },
    /// Any other rule, in words.
    #[error("{field}: {rule}")]
    Rule { field: String, rule: String },
}

impl ValidationError {
    /// The JSON path of the offending field.
    pub fn field(&self) -> &str {
        match self {
            Self::NonFinite { field, .. }
            | Self::OutOfRange { field, .. }
            | Self::WrongLength { field, .. }
            | Self::NotIncreasing { field, .. }
            | Self::WrongEndpoint { field, .. }
            | Self::Rule { field, .. } => field,
        }
    }

    /// The same error with `prefix.` put before its field path.
    pub fn within(mut self, prefix: &str) -> Self {
        let f = match &mut self {
            Self::NonFinite { field, .. }
            | Self::OutOfRange { field, .. }
            | Self::WrongLength { field, .. }
            | Self::NotIncreasing { field, .. }
            | Self::WrongEndpoint { field, .. }
            | Self::Rule { field, .. } => field,
        };
        *f = if f.starts_with('[') { format!("{prefix}{f}") } else { format!("{prefix}.{f}") };
        self
    }
}

/// Checks `value` is finite and inside `[min, max]`.
pub fn check_range(field: impl FnOnce() -> String, value: f64, min: f64, max: f64) -> Result<(), ValidationError> {
    if !value.is_finite() {
        return Err(ValidationError::NonFinite { field: field(), value });
    }
    if value < min || value > max {
        return Err(ValidationError::OutOfRange { field: field(), value, min, max });
    }
    Ok(())
}

/// Checks a 3x3 matrix: every entry finite and inside `[-limit, limit]`.
pub fn check_matrix(field: &str, m: &crate::ccm::Mat3, limit: f64) -> Result<(), ValidationError> {
    for (i, row) in m.iter().enumerate() {
        for (j, &v) in row.iter().enumerate() {
            check_range(|| format!("{field}[{i}][{j}]"), v, -limit, limit)?;
        }
    }
    Ok(())
}

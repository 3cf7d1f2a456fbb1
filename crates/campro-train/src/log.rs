//! The training log: one [`LogRow`] per round, as CSV ([`log_csv`], [`parse_log_csv`])
//! and as two SVG charts ([`plot_log`]).

use crate::error::{Result, TrainError};
use serde::{Deserialize, Deserializer, Serialize};

/// One line of the training log. Checkpoints keep the log, so a resumed run's log (and its
/// plots) covers the whole run. Values not measured are NaN (`null` in a checkpoint).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LogRow {
    /// 0 for pretraining (or the round a checkpoint without a log was resumed from), then 1, 2, ...
    pub round: usize,
    /// Training time since round 0, over all resumed parts (s).
    #[serde(deserialize_with = "nan_if_null")]
    pub seconds: f64,
    /// Attacker cross-entropy on its last batch.
    #[serde(deserialize_with = "nan_if_null")]
    pub attacker_ce: f64,
    /// Attacker top-1 on its last batch.
    #[serde(deserialize_with = "nan_if_null")]
    pub attacker_accuracy: f64,
    /// Protector loss `−log(1 − p_y)` on its last batch (rounds ≥ 1).
    #[serde(deserialize_with = "nan_if_null")]
    pub privacy_loss: f64,
    /// Detection loss L_det on the protector's last person batch (ω > 0, rounds ≥ 1).
    #[serde(deserialize_with = "nan_if_null")]
    pub detection_loss: f64,
    /// Top-1 of the attacker on the held-aside photos through the current camera.
    pub check_accuracy: Option<f64>,
    /// Validation privacy ([`crate::validation`]): top-1 of the pretrained face model's
    /// nearest class mean on the held-aside photos through the camera, at validation rounds.
    #[serde(default)]
    pub validation_top1: Option<f64>,
    /// Validation utility: person AP (0..1) of the detector on the set-aside COCO training
    /// images through the camera, at validation rounds with a utility player.
    #[serde(default)]
    pub validation_ap: Option<f64>,
}

/// JSON has no NaN: serde_json writes it as `null`, read back here as NaN.
pub(crate) fn nan_if_null<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// The CSV columns; logs written before the validation columns have the first seven.
const LOG_FIELDS: [&str; 9] = [
    "round",
    "seconds",
    "attacker_ce",
    "attacker_accuracy",
    "privacy_loss",
    "detection_loss",
    "check_accuracy",
    "validation_top1",
    "validation_ap",
];

/// The log as CSV (one line per round, a header, `NaN` where not measured, an empty
/// `check_accuracy`, `validation_top1` or `validation_ap` where not measured).
pub fn log_csv(log: &[LogRow]) -> String {
    let opt = |v: Option<f64>| v.map_or(String::new(), |c| format!("{c:.4}"));
    let mut csv = format!("{}\n", LOG_FIELDS.join(","));
    for r in log {
        csv += &format!(
            "{},{:.3},{:.6},{:.4},{:.6},{:.6},{},{},{}\n",
            r.round,
            r.seconds,
            r.attacker_ce,
            r.attacker_accuracy,
            r.privacy_loss,
            r.detection_loss,
            opt(r.check_accuracy),
            opt(r.validation_top1),
            opt(r.validation_ap)
        );
    }
    csv
}

/// Reads a log written by [`log_csv`] (or before the validation columns, with seven);
/// the error names the line and the field.
pub fn parse_log_csv(text: &str) -> Result<Vec<LogRow>> {
    let err = |line: usize, rule: String| TrainError::Log { line, rule };
    let mut lines = text.lines().enumerate();
    let fields = match lines.next().map(|(_, h)| h.trim()) {
        Some(h) if h == LOG_FIELDS.join(",") => 9,
        Some(h) if h == LOG_FIELDS[..7].join(",") => 7,
        _ => return Err(err(1, format!("expected the header {}", LOG_FIELDS.join(",")))),
    };
    lines
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, line)| {
            let f: Vec<&str> = line.split(',').map(str::trim).collect();
            if f.len() != fields {
                return Err(err(i + 1, format!("{} fields, expected {fields}", f.len())));
            }
            let num = |k: usize| f[k].parse::<f64>().map_err(|e| err(i + 1, format!("{}: {e}", LOG_FIELDS[k])));
            let opt = |k: usize| if f.get(k).is_none_or(|v| v.is_empty()) { Ok(None) } else { num(k).map(Some) };
            Ok(LogRow {
                round: f[0].parse().map_err(|e| err(i + 1, format!("round: {e}")))?,
                seconds: num(1)?,
                attacker_ce: num(2)?,
                attacker_accuracy: num(3)?,
                privacy_loss: num(4)?,
                detection_loss: num(5)?,
                check_accuracy: opt(6)?,
                validation_top1: opt(7)?,
                validation_ap: opt(8)?,
            })
        })
        .collect()
}

/// The log as two SVG charts: the losses (attacker cross-entropy, privacy loss) and the
/// attacker's accuracies (last batch, held-aside photos through the camera), by round.
pub fn plot_log(log: &[LogRow]) -> (String, String) {
    use campro_eval::plot::{chart, Series, Style};
    let series = |name: &str, f: &dyn Fn(&LogRow) -> Option<f64>| Series {
        name: name.into(),
        points: log.iter().filter_map(|r| f(r).map(|v| (r.round as f64, v))).collect(),
    };
    let losses = chart(
        "campro train: losses",
        "round",
        "loss",
        &[
            series("attacker CE", &|r| Some(r.attacker_ce)),
            series("privacy −log(1 − p_y)", &|r| Some(r.privacy_loss)),
            series("detection L_det", &|r| r.detection_loss.is_finite().then_some(r.detection_loss)),
        ],
        Style::Lines,
        None,
        None,
    );
    let acc = chart(
        "campro train: attacker accuracy and validation",
        "round",
        "top-1, AP",
        &[
            series("last batch", &|r| Some(r.attacker_accuracy)),
            series("held-aside, through camera", &|r| r.check_accuracy),
            series("validation top-1 (pretrained model)", &|r| r.validation_top1),
            series("validation person AP", &|r| r.validation_ap),
        ],
        Style::Lines,
        None,
        Some((0.0, 1.0)),
    );
    (losses, acc)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_csv_log_reads_back_with_its_nans_and_gaps() {
        let rows = vec![
            LogRow {
                round: 0,
                seconds: 1.5,
                attacker_ce: 2.25,
                attacker_accuracy: 0.5,
                privacy_loss: f64::NAN,
                detection_loss: f64::NAN,
                check_accuracy: Some(0.875),
                validation_top1: Some(0.0625),
                validation_ap: Some(0.25),
            },
            LogRow {
                round: 1,
                seconds: 7.125,
                attacker_ce: 3.0,
                attacker_accuracy: 0.25,
                privacy_loss: 0.5,
                detection_loss: 4.0,
                check_accuracy: None,
                validation_top1: None,
                validation_ap: None,
            },
        ];
        let csv = log_csv(&rows);
        assert_eq!(csv.lines().nth(1), Some("0,1.500,2.250000,0.5000,NaN,NaN,0.8750,0.0625,0.2500"));
        assert_eq!(csv.lines().nth(2), Some("1,7.125,3.000000,0.2500,0.500000,4.000000,,,"));
        let back = parse_log_csv(&csv).unwrap();
        assert_eq!(back[1], rows[1]);
        assert!(back[0].privacy_loss.is_nan() && back[0].check_accuracy == Some(0.875));
        assert_eq!((back[0].validation_top1, back[0].validation_ap), (Some(0.0625), Some(0.25)));
        // A log from before the validation columns still reads, without them.
        let old = parse_log_csv(&format!("{}\n3,1.0,2.0,0.5,0.1,NaN,0.25\n", LOG_FIELDS[..7].join(","))).unwrap();
        assert_eq!((old[0].round, old[0].check_accuracy, old[0].validation_top1), (3, Some(0.25), None));
        let bad = csv.replace("7.125", "x");
        assert!(
            parse_log_csv(&bad).unwrap_err().to_string().starts_with("line 3: seconds"),
            "{}",
            parse_log_csv(&bad).unwrap_err()
        );
        assert!(parse_log_csv("round,seconds\n").unwrap_err().to_string().contains("line 1: expected the header"));
        assert!(parse_log_csv(&format!("{}\n1,2\n", LOG_FIELDS.join(",")))
            .unwrap_err()
            .to_string()
            .contains("line 2: 2 fields"));
    }
}

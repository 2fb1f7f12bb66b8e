//! Judging a fit against the acceptance spec, and what a fit is calibrated with.

use trainer::acceptance::{self, Judged, Spec};
use trainer::evaluation::evaluate::RunEvaluation;
use trainer::fit::FitOutcome;
use trainer::fit::coverage::{InUse, model_range_c};
use trainer::provenance::ProvenanceRecord;
use trainer::records::Store;

/// What a fit is calibrated with and recorded in, beside its options: its provenance, the
/// spec it is judged against, the records store.
pub(super) struct Calibration<'a> {
    /// Where the blob comes from.
    pub(super) provenance: &'a ProvenanceRecord,
    /// The acceptance spec, if the unit is judged.
    pub(super) spec: Option<&'a Spec>,
    /// The records store, if the calibration is recorded.
    pub(super) store: Option<Store>,
}

/// The verdict of one axis's fit `outcome` (`axis`: `None` for a single-axis run) against
/// `spec`: its holdout runs among `evals`, its forecast, what its runs lack for the spec's
/// range of use (else `in_use`'s).
pub(super) fn judge_axis(
    spec: &Spec,
    in_use: &InUse,
    outcome: &FitOutcome,
    evals: &[(&str, RunEvaluation)],
    axis: Option<&str>,
) -> acceptance::Verdict {
    let missing_for = InUse {
        range_c: spec.use_range_c().or(in_use.range_c),
        ..*in_use
    };
    acceptance::judge(
        spec,
        &Judged {
            holdout: evals
                .iter()
                .filter(|(r, e)| *r == "holdout" && e.axis == axis)
                .map(|(_, e)| e)
                .collect(),
            forecast_in_use_std100_dph: outcome.predicted_in_use_std100_dph(),
            missing: outcome
                .bank_search()
                .map(|b| b.coverage.missing(&missing_for, model_range_c(&outcome.model))),
        },
    )
}

/// The verdict as `fit` prints it: `acceptance: pass`, or `FAIL` and a line per limit missed.
pub(super) fn verdict_text(v: &acceptance::Verdict) -> String {
    if v.passed() {
        "acceptance: pass".to_owned()
    } else {
        let mut t = "acceptance: FAIL".to_owned();
        for r in &v.reasons {
            t.push_str("\n  ");
            t.push_str(r);
        }
        t
    }
}

//! The accuracy tables `trainer eval` and `trainer fit` print: before/after figures
//! per run ([`print_table`]), the Allan noise terms ([`print_allan_table`]) and
//! the settled bias of soak plateaus ([`print_settled_table`]).

use std::io::Write;
use std::path::Path;

use crate::dataset::plateaus::SettledBias;

use super::allan;
use super::evaluate::*;

/// Writes a before/after table, one line per (role, evaluation).
/// A row per run, or per run and axis when a row names an axis (a multi-axis
/// run: the axis follows the run's name).
pub fn print_table(out: &mut impl Write, rows: &[(&str, &RunEvaluation)]) -> std::io::Result<()> {
    writeln!(
        out,
        "{:<10} {:<28}{} {:>11} {:>11} {:>7}  {:>11} {:>11} {:>7} {:>8}",
        "role",
        "run",
        axis_cell(rows, Some("axis")),
        "MSD before",
        "MSD after",
        "gain",
        "STD100 bef",
        "STD100 aft",
        "gain",
        "clamped"
    )?;
    writeln!(
        out,
        "{:<10} {:<28}{} {:>11} {:>11} {:>7}  {:>11} {:>11} {:>7} {:>8}",
        "",
        "",
        axis_cell(rows, Some("")),
        "[°²/h²]",
        "[°²/h²]",
        "[%]",
        "[°/h]",
        "[°/h]",
        "[%]",
        "[%]"
    )?;
    for (role, e) in rows {
        writeln!(
            out,
            "{:<10} {:<28}{} {:>11} {:>11} {:>7}  {:>11} {:>11} {:>7} {:>8}",
            role,
            table_name(&e.run),
            axis_cell(rows, e.axis),
            figure(e.msd_before_dph2, |v| format!("{v:.4e}")),
            figure(e.msd_after_dph2, |v| format!("{v:.4e}")),
            figure(e.msd_improvement_pct, |v| format!("{v:.1}")),
            figure(e.cluster_std_before_dph, |v| format!("{v:.4e}")),
            figure(e.cluster_std_after_dph, |v| format!("{v:.4e}")),
            figure(e.cluster_std_improvement_pct, |v| format!("{v:.1}")),
            figure(e.clamped_pct(), |v| format!("{v:.1}"))
        )?;
    }
    if rows.iter().any(|(_, e)| e.clamped_pct() > 0.0) {
        writeln!(
            out,
            "(clamped: samples whose inputs lay outside the model's training range, held at its edge (flag 1): \
             there the model extrapolates)"
        )?;
    }
    for (_, e) in rows.iter().filter(|(_, e)| e.reference == RUN_MEAN) {
        writeln!(
            out,
            "({}{}: no ref_dph column; the reference is the run's mean rate, so a constant bias is not seen)",
            table_name(&e.run),
            e.axis.map_or(String::new(), |a| format!(" axis {a}"))
        )?;
    }
    let short = |e: &RunEvaluation| {
        [
            e.msd_before_dph2,
            e.msd_after_dph2,
            e.cluster_std_before_dph,
            e.cluster_std_after_dph,
        ]
        .iter()
        .any(|v| !v.is_finite())
    };
    if rows.iter().any(|(_, e)| short(e)) {
        writeln!(
            out,
            "(—: not enough data for the figure: STD100 needs two 100-s clusters at least half full, a gain both figures)"
        )?;
    }
    if let Some((_, e)) = rows.iter().find(|(_, e)| e.basis.ends_with(BLOCK_MEANS)) {
        let merged = if e.basis == BLOCK_MEANS {
            String::new()
        } else {
            format!(
                " (--block-s blocks merged in pairs: a run past {} blocks has them merged)",
                crate::dataset::MAX_BLOCKS_PER_RUN
            )
        };
        writeln!(
            out,
            "(train: scored on the fit's {}{merged}, warm-up left out; `trainer eval` scores every sample)",
            e.basis
        )?;
    }
    Ok(())
}

/// The axis column of a table row: absent (empty) unless some row names an axis.
pub(super) fn axis_cell(rows: &[(&str, &RunEvaluation)], text: Option<&str>) -> String {
    if rows.iter().any(|(_, e)| e.axis.is_some()) {
        format!(" {:<4}", text.unwrap_or(""))
    } else {
        String::new()
    }
}

/// Writes the Allan read-offs (ARW, bias instability), one line per (role, evaluation).
pub fn print_allan_table(out: &mut impl Write, rows: &[(&str, &RunEvaluation)]) -> std::io::Result<()> {
    writeln!(
        out,
        "{:<10} {:<28}{} {:>11} {:>11}  {:>11} {:>11} {:>7} {:>4}",
        "role",
        "run",
        axis_cell(rows, Some("axis")),
        "ARW before",
        "ARW after",
        "BI before",
        "BI after",
        "at τ",
        "±"
    )?;
    writeln!(
        out,
        "{:<10} {:<28}{} {:>11} {:>11}  {:>11} {:>11} {:>7} {:>4}",
        "",
        "",
        axis_cell(rows, Some("")),
        "[°/√h]",
        "[°/√h]",
        "[°/h]",
        "[°/h]",
        "[s]",
        "[%]"
    )?;
    for (role, e) in rows {
        let after = &e.allan_after;
        writeln!(
            out,
            "{:<10} {:<28}{} {:>11} {:>11}  {:>11} {:>11} {:>7} {:>4}",
            role,
            table_name(&e.run),
            axis_cell(rows, e.axis),
            figure(e.allan_before.arw_deg_per_sqrt_h, |v| format!("{v:.3e}")),
            figure(after.arw_deg_per_sqrt_h, |v| format!("{v:.3e}")),
            e.allan_before.bias_instability_cell(),
            after.bias_instability_cell(),
            figure(after.floor_tau_s, |v| format!("{v:.0}")),
            figure(after.floor_uncertainty_pct, |v| format!("{v:.0}"))
        )?;
    }
    writeln!(out, "({}; at τ and ± of BI after)", allan::FLOOR_RULE)?;
    if rows
        .iter()
        .any(|(_, e)| !e.allan_after.bias_instability_dph.is_finite())
    {
        writeln!(out, "(—: the run is too short for an Allan deviation)")?;
    }
    Ok(())
}

/// What a run without settled plateaus reads as.
pub const NO_PLATEAU: &str = "no settled plateau (the loop never steady for 30 min)";

/// Writes the settled bias of every plateau before and after compensation,
/// a line per plateau, then each run's spread (max − min) or why it has
/// none ([`crate::dataset::plateaus`] states the rule). Evaluations scored
/// on block means (no settled figures) are left out.
pub fn print_settled_table(out: &mut impl Write, rows: &[(&str, &RunEvaluation)]) -> std::io::Result<()> {
    writeln!(
        out,
        "{:<28}{} {:>8} {:>7}  {:>21}  {:>21}  {:>7}",
        "run",
        axis_cell(rows, Some("axis")),
        "T loop",
        "steady",
        "bias before ± noise",
        "bias after ± noise",
        "outside"
    )?;
    writeln!(
        out,
        "{:<28}{} {:>8} {:>7}  {:>21}  {:>21}  {:>7}",
        "",
        axis_cell(rows, Some("")),
        "[°C]",
        "[min]",
        "[°/h]",
        "[°/h]",
        "[%]"
    )?;
    let bias = |b: f64, noise: f64| {
        format!(
            "{} ± {}",
            figure(b, |v| format!("{v:+.4}")),
            figure(noise, |v| format!("{v:.4}"))
        )
    };
    let mut spreads = Vec::new();
    for (_, e) in rows {
        let Some(settled) = &e.settled else { continue };
        let name = table_name(&e.run);
        let axis = e.axis.map_or(String::new(), |a| format!(" axis {a}"));
        for p in &settled.plateaus {
            writeln!(
                out,
                "{:<28}{} {:>8.2} {:>7.0}  {:>21}  {:>21}  {:>7.0}",
                name,
                axis_cell(rows, e.axis),
                p.temp_c,
                p.steady_s / 60.0,
                bias(p.bias_before_dph, p.noise_before_dph),
                bias(p.bias_after_dph, p.noise_dph),
                p.outside_range_pct
            )?;
        }
        spreads.push(match (settled.settled_spread_before_dph, settled.settled_spread_dph) {
            (Some(before), Some(after)) => format!(
                "{name}{axis}: settled spread (max − min over {} plateaus) before {before:.4} °/h, after {after:.4} °/h{}",
                settled.plateaus.len(),
                in_range_words(settled)
            ),
            _ if settled.plateaus.len() == 1 => format!("{name}{axis}: one settled plateau, no spread"),
            _ => format!("{name}{axis}: {NO_PLATEAU}"),
        });
    }
    for line in spreads {
        writeln!(out, "{line}")?;
    }
    writeln!(out, "({})", crate::dataset::plateaus::rule_text())?;
    writeln!(out, "({})", crate::dataset::plateaus::outside_rule_text())?;
    Ok(())
}

/// The spread inside the model's training range, as the spread line
/// appends it where some plateau lies outside (`"; inside the training
/// range 0.0123 °/h over 6 plateaus"`), else nothing.
pub fn in_range_words(settled: &SettledBias) -> String {
    let inside = settled.plateaus.iter().filter(|p| !p.outside_range()).count();
    if inside == settled.plateaus.len() {
        return String::new();
    }
    match settled.settled_spread_in_range_dph {
        Some(spread) => format!("; inside the training range {spread:.4} °/h over {inside} plateaus"),
        None => format!("; {inside} plateaus inside the training range, no spread there"),
    }
}

/// A table cell: `v` as `show` writes it, or "—" when there is no figure
/// (NaN or ±∞: too few samples or clusters), never "NaN".
pub(crate) fn figure(v: f64, show: impl Fn(f64) -> String) -> String {
    if v.is_finite() { show(v) } else { "—".to_owned() }
}

/// A run's file name, shortened from the left to fit the table's column.
pub(super) fn table_name(run: &str) -> String {
    let name = Path::new(run)
        .file_name()
        .map_or(run.to_owned(), |n| n.to_string_lossy().into_owned());
    truncate(&name, 28)
}

pub(super) fn truncate(s: &str, max: usize) -> String {
    if s.chars().count() <= max {
        s.to_owned()
    } else {
        format!(
            "…{}",
            s.chars()
                .rev()
                .take(max - 1)
                .collect::<Vec<_>>()
                .into_iter()
                .rev()
                .collect::<String>()
        )
    }
}

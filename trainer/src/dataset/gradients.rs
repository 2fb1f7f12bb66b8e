//! Multi-point temperature inputs (RLG paper, Li et al., Sensors 2015): the
//! thermometers `temp_a` … `temp_h`, every pairwise gradient T_i − T_j, their
//! block means (the paper's 100-sample smoothing) and the Pearson
//! correlation of each candidate with the gyro's bias, printed as a matrix
//! like the paper's Table 3, with the inputs a threshold or a top-N rule
//! selects. `trainer correlate` is the command.
//!
//! The bias is rate − `ref_dph` (the rate alone when the run has no
//! reference: a constant offset does not change a correlation).

use std::path::PathBuf;

use rbf_core::features::Probe;
use rbf_core::record;

use crate::dataset::Blocks;
use crate::reading::run::RunReader;
use crate::reading::run::rows::RunError;

/// Column names of the thermometers, in the matrix's order.
pub const THERMOMETERS: [&str; 8] = record::column::THERMOMETERS;

/// Block means of the thermometers a run has, and of its bias.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MultiBlocks {
    /// Which of [`THERMOMETERS`] the runs have (indices into it).
    pub sensors: Vec<usize>,
    /// Per block, the mean of each present thermometer (in `sensors`' order), °C.
    pub temps: Vec<Vec<f64>>,
    /// Per block, the mean bias, °/h.
    pub bias: Vec<f64>,
}

impl MultiBlocks {
    /// Groups of `group` consecutive blocks of one run averaged (a short last
    /// group of a run dropped), from training blocks whose inputs are the
    /// temperatures of `sensors` in order (`trainer fit --method svr-pso`
    /// computes those with rbf-core, as the firmware would).
    pub fn from_blocks(blocks: &Blocks, sensors: &[usize], group: usize) -> MultiBlocks {
        let group = group.max(1);
        let mut out = MultiBlocks {
            sensors: sensors.to_vec(),
            ..MultiBlocks::default()
        };
        let mut start = 0;
        while start < blocks.len() {
            let run = blocks.run[start];
            let end = (start..blocks.len())
                .find(|&i| blocks.run[i] != run)
                .unwrap_or(blocks.len());
            for chunk_start in (start..end).step_by(group).filter(|c| c + group <= end) {
                let rows = chunk_start..chunk_start + group;
                let mean = |f: &dyn Fn(usize) -> f64| rows.clone().map(f).sum::<f64>() / group as f64;
                out.temps
                    .push((0..sensors.len()).map(|k| mean(&|i| blocks.x[i][k])).collect());
                out.bias.push(mean(&|i| blocks.y[i]));
            }
            start = end;
        }
        out
    }
}

/// Reads `paths` and averages every `block_samples` consecutive rows (a
/// short last block of a run is dropped). All runs must have the same
/// thermometers, at least two.
pub fn row_block_means(paths: &[PathBuf], block_samples: usize) -> Result<MultiBlocks, RunError> {
    let mut out = MultiBlocks::default();
    for (n, path) in paths.iter().enumerate() {
        let mut reader = RunReader::open(path)?;
        reader.header().require_single_axis()?;
        let sensors: Vec<usize> = reader.columns().thermometers().iter().collect();
        let header_error = |message: String| RunError::Format {
            path: path.clone(),
            line: reader.line_number(),
            message,
        };
        if sensors.len() < 2 {
            return Err(header_error(format!(
                "header has {} of the thermometer columns temp_a … temp_h; gradients need at least two",
                sensors.len()
            )));
        }
        if n == 0 {
            out.sensors.clone_from(&sensors);
        } else if out.sensors != sensors {
            return Err(header_error("its thermometers differ from the first run's".into()));
        }
        let (mut sum_t, mut sum_b, mut count) = (vec![0.0; sensors.len()], 0.0, 0usize);
        while let Some((_, row)) = reader.next_parsed()? {
            for (slot, &k) in sum_t.iter_mut().zip(&sensors) {
                *slot += row.temps_c[k].unwrap_or(f64::NAN);
            }
            sum_b += row.rate_dph - row.ref_dph.unwrap_or(0.0);
            count += 1;
            if count == block_samples.max(1) {
                out.temps.push(sum_t.iter().map(|s| s / count as f64).collect());
                out.bias.push(sum_b / count as f64);
                sum_t.iter_mut().for_each(|s| *s = 0.0);
                (sum_b, count) = (0.0, 0);
            }
        }
    }
    Ok(out)
}

/// Pearson correlation of `x` with `y`; 0 when either is constant.
pub fn pearson(x: &[f64], y: &[f64]) -> f64 {
    let n = x.len().min(y.len());
    if n < 2 {
        return 0.0;
    }
    let mean = |v: &[f64]| v.iter().take(n).sum::<f64>() / n as f64;
    let (mx, my) = (mean(x), mean(y));
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (a, b) in x.iter().zip(y).take(n) {
        let (dx, dy) = (a - mx, b - my);
        sxy += dx * dy;
        sxx += dx * dx;
        syy += dy * dy;
    }
    if sxx > 0.0 && syy > 0.0 {
        sxy / (sxx * syy).sqrt()
    } else {
        0.0
    }
}

/// One candidate input: a thermometer (i == j) or the gradient T_i − T_j (i < j),
/// indices into [`MultiBlocks::sensors`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub struct Candidate {
    /// First thermometer.
    pub i: usize,
    /// Second thermometer (== `i` for the temperature itself).
    pub j: usize,
}

impl Candidate {
    /// The model input this candidate is, given the thermometers behind the
    /// matrix's rows (`sensors`, indices into [`THERMOMETERS`]).
    pub fn probe(self, sensors: &[usize]) -> Probe {
        let at = |k: usize| sensors.get(k).copied().unwrap_or(0) as u8;
        if self.i == self.j {
            Probe::Temp(at(self.i))
        } else {
            Probe::Gradient(at(self.i), at(self.j))
        }
    }

    /// The candidate `probe` is, if its thermometers are among `sensors`
    /// (a gradient listed as i < j in the matrix; T_j − T_i is its negative).
    pub fn of_probe(probe: Probe, sensors: &[usize]) -> Option<Candidate> {
        let row = |t: u8| sensors.iter().position(|&s| s == t as usize);
        let (i, j) = match probe {
            Probe::Temp(t) => (row(t)?, row(t)?),
            Probe::Gradient(a, b) => (row(a)?, row(b)?),
        };
        Some(Candidate {
            i: i.min(j),
            j: i.max(j),
        })
    }
}

/// Correlations of every candidate with the bias: `r[i][j]` for the
/// thermometer (i == j) or the gradient T_i − T_j (i < j; symmetric, so
/// `r[j][i] = −r[i][j]`).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct CorrelationTable {
    /// Column names of the thermometers, in the matrix's order.
    pub names: Vec<String>,
    /// The correlation matrix.
    pub r: Vec<Vec<f64>>,
    /// Blocks the correlations are computed over.
    pub blocks: usize,
}

/// The candidates' correlations with the bias over `blocks`.
pub fn correlations(blocks: &MultiBlocks) -> CorrelationTable {
    let m = blocks.sensors.len();
    let column = |i: usize, j: usize| -> Vec<f64> {
        blocks
            .temps
            .iter()
            .map(|t| if i == j { t[i] } else { t[i] - t[j] })
            .collect()
    };
    // Upper triangle and diagonal computed; the lower triangle is their negative.
    let upper: Vec<Vec<f64>> = (0..m)
        .map(|i| {
            (0..m)
                .map(|j| {
                    if j >= i {
                        pearson(&column(i, j), &blocks.bias)
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
    let r: Vec<Vec<f64>> = (0..m)
        .map(|i| {
            (0..m)
                .map(|j| if j >= i { upper[i][j] } else { -upper[j][i] })
                .collect()
        })
        .collect();
    CorrelationTable {
        names: blocks.sensors.iter().map(|&k| THERMOMETERS[k].to_owned()).collect(),
        r,
        blocks: blocks.bias.len(),
    }
}

/// How inputs are chosen from the candidates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Selection {
    /// Every candidate with |r| ≥ the threshold (the paper: 0.9).
    Threshold(f64),
    /// The N candidates of largest |r|.
    Top(usize),
}

/// The candidates `selection` keeps, by falling |r| (ties in matrix order).
pub fn select(table: &CorrelationTable, selection: Selection) -> Vec<Candidate> {
    let m = table.names.len();
    let mut all: Vec<(Candidate, f64)> = (0..m)
        .flat_map(|i| (i..m).map(move |j| Candidate { i, j }))
        .map(|c| (c, table.r[c.i][c.j].abs()))
        .collect();
    all.sort_by(|a, b| b.1.total_cmp(&a.1));
    match selection {
        Selection::Threshold(t) => all.into_iter().filter(|(_, r)| *r >= t).map(|(c, _)| c).collect(),
        Selection::Top(n) => all.into_iter().take(n).map(|(c, _)| c).collect(),
    }
}

/// A candidate's name: `temp_b` or `temp_b−temp_d`.
pub fn candidate_name(table: &CorrelationTable, c: Candidate) -> String {
    if c.i == c.j {
        table.names[c.i].clone()
    } else {
        format!("{}−{}", table.names[c.i], table.names[c.j])
    }
}

/// The matrix as text: row i, column j holds r of T_i (diagonal) or of
/// T_i − T_j (off the diagonal); selected candidates are marked `*`.
pub fn format_table(table: &CorrelationTable, selected: &[Candidate]) -> String {
    let mut s = format!(
        "Pearson r with the bias, {} block means; diagonal: the temperature, row i column j: T_i − T_j (* selected)\n",
        table.blocks
    );
    s.push_str(&format!("{:>8}", ""));
    for n in &table.names {
        s.push_str(&format!("{n:>9}"));
    }
    s.push('\n');
    for (i, row) in table.r.iter().enumerate() {
        s.push_str(&format!("{:>8}", table.names[i]));
        for (j, r) in row.iter().enumerate() {
            let c = Candidate {
                i: i.min(j),
                j: i.max(j),
            };
            let mark = if selected.contains(&c) { '*' } else { ' ' };
            s.push_str(&format!("{r:>8.3}{mark}"));
        }
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn write_run(dir: &Path, name: &str, rows: usize, bias: impl Fn(&[f64]) -> f64) -> PathBuf {
        let mut text = String::from("time_s,rate_dph,temp_a,temp_b,temp_c,temp_d\n");
        for k in 0..rows {
            let t = k as f64;
            // Four thermometers with different, non-proportional histories.
            let temps = [
                20.0 + 0.01 * t,
                20.0 + 5.0 * (t / 300.0).sin(),
                20.0 + 0.004 * t + 2.0 * (t / 70.0).cos(),
                25.0 - 0.003 * t,
            ];
            let b = bias(&temps);
            text.push_str(&format!(
                "{:.2},{b:.6},{:.4},{:.4},{:.4},{:.4}\n",
                t * 0.01,
                temps[0],
                temps[1],
                temps[2],
                temps[3]
            ));
        }
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        path
    }

    #[test]
    fn the_gradient_that_drives_the_bias_correlates_best_and_is_selected() {
        let dir = tempfile::tempdir().unwrap();
        let run = write_run(dir.path(), "run.csv", 20_000, |t| 0.5 * (t[1] - t[2]));
        let blocks = row_block_means(&[run], 100).unwrap();
        assert_eq!(blocks.temps.len(), 200);
        assert_eq!(blocks.sensors, [0, 1, 2, 3]);
        let table = correlations(&blocks);
        assert!((table.r[1][2] - 1.0).abs() < 1e-6, "r(T_b − T_c) = {}", table.r[1][2]);
        assert!((table.r[2][1] + 1.0).abs() < 1e-6, "antisymmetric");
        let top = select(&table, Selection::Top(1));
        assert_eq!(top, [Candidate { i: 1, j: 2 }]);
        assert_eq!(candidate_name(&table, top[0]), "temp_b−temp_c");
        let strong = select(&table, Selection::Threshold(0.9));
        assert!(strong.contains(&Candidate { i: 1, j: 2 }));
        assert!(strong.iter().all(|c| table.r[c.i][c.j].abs() >= 0.9));
        let text = format_table(&table, &top);
        assert!(text.contains("temp_b") && text.contains("1.000*"), "{text}");
    }

    #[test]
    fn runs_without_two_thermometers_or_with_bad_values_are_refused_with_their_place() {
        let dir = tempfile::tempdir().unwrap();
        let single = dir.path().join("single.csv");
        std::fs::write(&single, "# sample_rate_hz: 1\n\ntime_s,rate_dph,temp_c\n0,1,20\n").unwrap();
        let err = row_block_means(&[single], 100).unwrap_err().to_string();
        assert!(err.contains("single.csv:3:") && err.contains("at least two"), "{err}");
        let bad = dir.path().join("bad.csv");
        std::fs::write(&bad, "time_s,rate_dph,temp_a,temp_b\n0,1,20,21\n0.01,1,20,x\n").unwrap();
        let err = row_block_means(&[bad], 100).unwrap_err().to_string();
        assert_eq!(
            err,
            format!(
                "{}:3: column temp_b (field 4): \"x\" is not a number",
                dir.path().join("bad.csv").display()
            )
        );
    }

    #[test]
    fn pearson_of_constant_or_short_series_is_zero() {
        assert_eq!(pearson(&[1.0, 1.0, 1.0], &[1.0, 2.0, 3.0]).to_bits(), 0.0f64.to_bits());
        assert_eq!(pearson(&[1.0], &[2.0]).to_bits(), 0.0f64.to_bits());
        assert!((pearson(&[1.0, 2.0, 3.0], &[-2.0, -4.0, -6.0]) + 1.0).abs() < 1e-12);
    }
}

//! `trainer fit`'s arguments, their parsers and the checks on them alone.

use std::path::PathBuf;

use clap::builder::RangedU64ValueParser;
use rbf_core::features::Probe;
use trainer::fit::coverage::InUse;
use trainer::fit::{CenterBudget, FitOptions, LagBankOptions, Method, RbfInputs, RbfSearch, SvrInputs, SvrOptions};
use trainer::reading::limits::MAX_FOLDS;

use super::super::common::{ForceArg, JsonArg, SelectArgs};
use super::super::values::{FeaturesArg, MethodArg};

/// Fit a bias model to recorded chamber runs and write the model blob.
///
/// The model's inputs are computed per sample by rbf-core, as the firmware
/// does, then averaged over blocks together with the bias target
/// `rate_dph − ref_dph` (or minus the run mean without ref_dph). The default
/// is the thermal lag bank: the mean coil temperature T̂ and the loop
/// temperature's rates through 4–5 derivative filters, its filters, coil lags
/// and Shupe gain identified from the runs and chosen on held-out thermal
/// events (or whole runs, or the --validate runs); a cubic in T̂ and the rates,
/// linear, with ridge weights. The other RBF forms (--features paper: T, ΔT,
/// T×ΔT; multiscale) choose Gaussian centres by orthogonal least squares, with
/// the ΔT window, width, ridge strength and number of centres chosen on the
/// --validate runs or by contiguous 5-fold validation. Prints the model as it
/// is, a before/after accuracy table and what the training covered, then
/// writes the blob.
///
/// Runs with rate_x_dph, rate_y_dph, rate_z_dph (all runs the same axes):
/// every axis is fitted as above on its own rate, thermometer and reference,
/// and one multi-axis blob holds the axis models; the table has a row per run
/// and axis.
#[derive(clap::Args, Debug)]
#[command(after_help = "Example:\n  trainer fit chamber.csv --validate check.csv -o model.bin --report fit-report")]
pub struct Args {
    /// Training runs (recorded-run CSV with temp_c).
    #[arg(required = true, value_name = "RUN.csv", help_heading = "Data")]
    pub(super) runs: Vec<PathBuf>,
    /// Runs that choose the hyper-parameters (repeatable).
    ///
    /// Used only to choose hyper-parameters and report generalisation.
    #[arg(long, value_name = "RUN.csv", help_heading = "Data")]
    pub(super) validate: Vec<PathBuf>,
    /// Runs only reported, never used to choose.
    ///
    /// Reported in the accuracy table and never used to choose anything: an honest
    /// test of generalisation.
    #[arg(long, value_name = "RUN.csv", help_heading = "Data")]
    pub(super) holdout: Vec<PathBuf>,
    /// Multi-axis runs: a model per axis, never one shared basis.
    ///
    /// For the per-axis three-axis firmware image, stm32f405-axes;
    /// stm32f405-axes-shared takes the joint model's blob.
    #[arg(long, help_heading = "Model")]
    pub(super) no_joint: bool,
    /// Multi-axis runs on one thermometer: one shared basis, whatever it costs.
    ///
    /// Writes the joint model even where an axis loses more than 0.5 points
    /// (100-s cluster STD) with it against its own fit; the firmware then
    /// evaluates one basis for every axis (image stm32f405-axes-shared).
    #[arg(long, help_heading = "Model", conflicts_with = "no_joint")]
    pub(super) joint: bool,
    /// Averaging block for training, s (long runs merge blocks in pairs).
    ///
    /// A run past 32768 blocks has them merged in pairs into blocks twice as
    /// long, as often as it takes (docs/methods.md, "Large runs").
    #[arg(long, value_name = "SECONDS", default_value_t = 1.0, help_heading = "Data")]
    pub(super) block_s: f64,
    /// Model form (see --help).
    ///
    /// rbf = Gaussian RBF network (inputs: --features); rbf2 = RBF on (T, ΔT), the IFOG
    /// paper's model before its modification; poly3 = cubic in T (PX4/ArduPilot form);
    /// svr-pso = ε-SVR with σ, C, ε tuned by particle swarm on 3 contiguous folds (the RLG
    /// paper's method), deployed as an RBF network with one width (support vectors reduced by
    /// OLS to --centers, else --max-centers, when there are more); its inputs: on runs with
    /// thermometers temp_a … temp_h, the subset of thermometers that validates best on the
    /// same folds (every subset scored by a fast Gaussian + linear ridge network; the gradients
    /// between the chosen ones are in the model's linear span), or the temperatures and
    /// gradients the RLG paper's correlation rule selects (--select-threshold 0.9,
    /// --select-top N), or named ones (--inputs); else (T, ΔT, T×ΔT) (ΔT window: the middle of
    /// --dt-window-s).
    #[arg(long, value_enum, default_value_t = MethodArg::Rbf, hide_possible_values = true, help_heading = "Model")]
    pub(super) method: MethodArg,
    /// Inputs of --method rbf (see --help).
    ///
    /// Default: the thermal lag bank, or the response bank below where the lag bank's residual
    /// on the training runs is above 1/0.6 × the response bank's (a coil unlike the one it
    /// encodes; `fit` prints both). lag-bank = the thermal lag bank alone: the mean coil temperature
    /// T̂ = T + Σ a_k·ΔT_k and the loop temperature's rates ΔT_k through 4–5 derivative
    /// filters from 15 s to 2 h, times a Shupe gain linear in T̂; a cubic in T̂ and the rates
    /// linear; filter set, coil lags a_k and gain identified from the runs and chosen by how
    /// well they predict held-out thermal events (or whole runs, or --validate runs); past the
    /// covered range of T̂ the cubic continues along its tangent, or itself for one band where
    /// an edge test on the outer 30 % of the range trusts it; Gaussians over T̂ only with
    /// --centers K (they bend the curve near the range's ends and extrapolate worse). It
    /// holds on temperature histories unlike the chamber's (cold starts, ambient steps, fast
    /// swings). multiscale = T, ΔT over three time scales (τ, 16τ, 256τ), T×ΔT₁, T×ΔT₂,
    /// T×ΔT₃ and T²×ΔT₂, Gaussians over T and the ΔT terms linear (the mean coil temperature
    /// lags the sensor in proportion to the rate: first-order terms of that lag);
    /// multiscale-second-order = the same with the second-order term ΔT₃² in place
    /// of T×ΔT₁; multiscale-validated = both fitted from one pass over the data, the
    /// second-order set also in its lagged forms (Gaussians over the mean coil temperature
    /// estimate T − L·ΔT₃, coil lag L of 10, 20, 40 or 80 min, at the second-order set's
    /// window and width) and, when that family already validates better than the first-order
    /// set, all of them again with the slowest window 1.25× longer (320τ: it should follow the
    /// coil's slowest radial mode), the best of these kept only when its validation RMS is
    /// below 0.9 × the first-order one (a term fitted at one ramp rate must earn its
    /// extrapolation); paper = (T, ΔT, T×ΔT) with Gaussians over all, the IFOG paper's network;
    /// response-bank = the thermal response bank alone: 12 derivative filters from 10 s to 1.1 h
    /// on T, (T − T₀)² and (T − T₀)³, a static cubic in T − T₀ (T₀ the middle of the covered
    /// range, tangent beyond it), five free mixtures of the filters' rates (R₀, (T − T₀)·R₁,
    /// (T − T₀)²·R₂ and the filtered square and cube), fitted by one ridge regression on 10-s
    /// block means whose penalty grows with each filter's time constant, so that responses of
    /// hours a chamber run barely excites stay small (docs/methods.md).
    #[arg(long, value_enum, hide_possible_values = true, help_heading = "Model")]
    pub(super) features: Option<FeaturesArg>,
    /// Use exactly K Gaussian centres (1–64; 1–16 per axis on multi-axis runs).
    ///
    /// Fewer if OLS finds fewer independent ones; without it K ≤ --max-centers is chosen
    /// on validation, except for the lag bank, which has none unless asked.
    #[arg(long, value_name = "K", value_parser = centers_parser(), help_heading = "Model")]
    pub(super) centers: Option<usize>,
    /// Most centres tried (1–64, default 32; 16 per axis on IMUs).
    ///
    /// The firmware's evaluation cost grows with K; the three-axis firmware holds 16
    /// centres per axis. Not with --centers, which fixes K.
    #[arg(long, value_name = "K", value_parser = centers_parser(), help_heading = "Search")]
    pub(super) max_centers: Option<usize>,
    /// ΔT filter time constants to choose from, s.
    ///
    /// Comma-separated; for multiscale the fastest of three, the others 16 and 256 times
    /// it; 0 = one-sample difference (IFOG Eq. 22). Default: choose among 15, 60 and 240 s.
    #[arg(
        long = "dt-window-s",
        alias = "rate-window-s",
        value_name = "SECONDS",
        value_delimiter = ',',
        help_heading = "Search"
    )]
    pub(super) dt_window_s: Vec<f32>,
    /// Folds per run without --validate (2–20).
    ///
    /// Validation splits each training run into N contiguous folds when no --validate
    /// runs are given.
    #[arg(long, value_name = "N", default_value_t = 5, help_heading = "Search",
          value_parser = RangedU64ValueParser::<usize>::new().range(2..=MAX_FOLDS))]
    pub(super) folds: usize,
    /// Gyro serial number stored in the blob (≤ 32 bytes).
    #[arg(long, help_heading = "Model")]
    pub(super) serial: Option<String>,
    /// Acceptance spec (TOML) to judge the unit against.
    ///
    /// Limits on every holdout run, on the forecast and on coverage (docs/production.md).
    /// The verdict is printed and in the JSON (`acceptance`); the spec's SHA-256 goes into
    /// the blob's provenance. A unit that misses a limit is still written, and the command
    /// exits 3.
    #[arg(long, value_name = "SPEC.toml", help_heading = "Model")]
    pub(super) spec: Option<PathBuf>,
    /// Also record this calibration in STORE (SQLite file or postgres://…).
    ///
    /// Needs --serial. One record (per axis) with the blob, its provenance, the figures and the verdict,
    /// written after the blob; a store that cannot be written fails the fit before it
    /// starts. `trainer history SERIAL --records STORE` lists them (docs/production.md).
    #[arg(long, value_name = "STORE", requires = "serial", help_heading = "Output")]
    pub(super) records: Option<String>,
    /// Batch id recorded in the blob's provenance (`trainer batch` passes it).
    #[arg(long, value_name = "ID", hide = true)]
    pub(super) batch: Option<String>,
    #[command(flatten)]
    pub(super) select: SelectArgs,
    /// svr-pso: these inputs, not a selection.
    ///
    /// Comma-separated temperatures and gradients, e.g. `temp_d,temp_c-temp_d,temp_a-temp_b`
    /// (at most 8).
    #[arg(long, value_name = "LIST", value_delimiter = ',', value_parser = parse_probe,
          help_heading = "Multi-point")]
    pub(super) inputs: Option<Vec<Probe>>,
    /// Model blob to write.
    ///
    /// postcard + CRC-32; flash it into the firmware's model region.
    #[arg(short, long, value_name = "MODEL.bin", help_heading = "Output")]
    pub(super) output: PathBuf,
    #[command(flatten)]
    pub(super) json: JsonArg,
    #[command(flatten)]
    pub(super) force: ForceArg,
    /// Also write plots, table and report into DIR.
    ///
    /// What `trainer report` writes for the model on every run of the fit (bias against
    /// loop temperature with the model overlaid and the residual, rate before and after,
    /// Allan deviation, report.md, report.json), plus fit.txt: what this command prints.
    #[arg(long, value_name = "DIR", help_heading = "Output")]
    pub(super) report: Option<PathBuf>,
    /// No progress bar.
    #[arg(short, long, help_heading = "Output")]
    pub(super) quiet: bool,
    /// Accept runs implausible as gyro recordings.
    ///
    /// By default the fit refuses, naming the reason, training runs whose loop
    /// temperature leaves −60 … 100 °C (°F?), and holdouts whose loop temperature does
    /// or changes faster than 20 °C/min by time_s (in hours?).
    #[arg(long, help_heading = "Data")]
    pub(super) allow_implausible: bool,
    /// Loop-temperature range of use, °C (MIN,MAX).
    ///
    /// The range the model will be used over. The `missing:` lines then say when the training runs' loop did not come within 5 % of
    /// the range of each end (the model extrapolates there), e.g. a chamber that went to
    /// −40 … 60 °C with holds too short for the loop to follow. Without it they judge the
    /// range the loop covered and say where it turned before it settled.
    #[arg(
        long = "use-range-c",
        value_name = "MIN,MAX",
        value_delimiter = ',',
        allow_hyphen_values = true,
        help_heading = "Data"
    )]
    pub(super) use_range_c: Option<Vec<f64>>,
    /// Fastest loop-temperature change in use, °C/min (either sign).
    ///
    /// The `missing:` lines then say when the runs' fastest filter (τ 15 s) never read it
    /// both rising and falling: faster changes extrapolate the rate weights. (Only in --help:
    /// -h fits a screen.)
    #[arg(long, value_name = "C_PER_MIN", help_heading = "Data", hide_short_help = true)]
    pub(super) use_rate_c_per_min: Option<f64>,
}

impl Args {
    /// The fit's options from the arguments, refusing what the method asked
    /// for would ignore, naming why: `--max-centers` beside `--centers`,
    /// either of them with a model without Gaussians (a cubic in T, the response bank),
    /// `--dt-window-s` with a model whose rate filters are fixed (the lag
    /// bank, the response bank, a cubic in T) or outside 0 … 86400 s,
    /// `--inputs` with a method other than svr-pso or naming an input twice,
    /// a block length or a correlation rule out of range.
    pub(super) fn fit_options(&self) -> anyhow::Result<FitOptions> {
        trainer::reading::limits::check_block_s(self.block_s)?;
        let selection = self.select.selection()?;
        check_distinct_inputs(self.inputs.as_deref().unwrap_or_default())?;
        let centers = match (self.centers, self.max_centers) {
            (Some(k), Some(max)) => anyhow::bail!(
                "--centers {k} with --max-centers {max}: --max-centers bounds the search for K, which --centers \
                 fixes; give one of them"
            ),
            (Some(k), None) => CenterBudget::Fixed(k),
            (None, Some(max)) => CenterBudget::UpTo(max),
            (None, None) => CenterBudget::DEFAULT,
        };
        let fixed_filters = match (self.method, self.features) {
            (MethodArg::Poly3, _) => Some("--method poly3 is a cubic in T, with no ΔT filter"),
            (MethodArg::Rbf, None | Some(FeaturesArg::LagBank)) => Some(
                "the thermal lag bank (the default) identifies its own filters (τ 15 s … 2 h); --dt-window-s is for \
                 --features multiscale…, paper, --method rbf2 or svr-pso",
            ),
            (MethodArg::Rbf, Some(FeaturesArg::ResponseBank)) => Some(
                "the response bank has its 12 filters fixed (10 s … 1.1 h); --dt-window-s is for --features \
                 multiscale…, paper, --method rbf2 or svr-pso",
            ),
            _ => None,
        };
        let no_gaussians = match (self.method, self.features) {
            (MethodArg::Poly3, _) => Some("--method poly3 is a cubic in T, with no Gaussians"),
            (MethodArg::Rbf, Some(FeaturesArg::ResponseBank)) => {
                Some("the response bank is linear in its filters, with no Gaussians")
            }
            _ => None,
        };
        if let Some(why) = no_gaussians
            && (self.centers.is_some() || self.max_centers.is_some())
        {
            anyhow::bail!("--centers and --max-centers would be ignored: {why}");
        }
        if let Some(why) = fixed_filters
            && !self.dt_window_s.is_empty()
        {
            anyhow::bail!("--dt-window-s would be ignored: {why}");
        }
        anyhow::ensure!(
            self.inputs.is_none() || self.method == MethodArg::SvrPso,
            "--inputs would be ignored: it names the multi-point inputs of --method svr-pso; --method {} takes its \
             inputs from --features",
            clap::ValueEnum::to_possible_value(&self.method).map_or_else(String::new, |v| v.get_name().to_owned())
        );
        anyhow::ensure!(
            self.dt_window_s
                .iter()
                .all(|w| w.is_finite() && (0.0..=86_400.0).contains(w)),
            "--dt-window-s values must be 0 … 86400 s"
        );
        let search = RbfSearch {
            centers,
            rate_windows_s: if self.dt_window_s.is_empty() {
                RbfSearch::default().rate_windows_s
            } else {
                self.dt_window_s.clone()
            },
            ..RbfSearch::default()
        };
        let rbf = |inputs| Method::Rbf {
            inputs,
            search: search.clone(),
        };
        let method = match (self.method, self.features.map(|f| (f, f.rbf_inputs()))) {
            (MethodArg::Rbf, Some((_, Some(inputs)))) => rbf(inputs),
            (MethodArg::Rbf, Some((FeaturesArg::ResponseBank, _))) => Method::ResponseBank,
            (MethodArg::Rbf, Some((FeaturesArg::MultiscaleValidated, _))) => Method::MultiscaleValidated(search),
            // The lag bank; by default choosing between it and the response bank.
            (MethodArg::Rbf, _) => Method::LagBank(LagBankOptions {
                centers: centers.fixed(),
                structure_choice: self.features.is_none(),
            }),
            (MethodArg::Rbf2, _) => rbf(RbfInputs::TempRate),
            (MethodArg::Poly3, _) => Method::Poly3,
            (MethodArg::SvrPso, _) => Method::SvrPso(SvrOptions {
                centers,
                rate_windows_s: search.rate_windows_s,
                inputs: match (&self.inputs, selection) {
                    (Some(named), _) => SvrInputs::Named(named.clone()),
                    (None, Some(rule)) => SvrInputs::Rule(rule),
                    (None, None) => SvrInputs::BestSubset,
                },
            }),
        };
        Ok(FitOptions {
            method,
            block_s: self.block_s,
            folds: self.folds,
            serial: self.serial.clone(),
            progress: !self.quiet,
        })
    }

    /// The range and rates of use given, checked.
    pub fn in_use(&self) -> anyhow::Result<InUse> {
        let range_c = match self.use_range_c.as_deref() {
            None => None,
            Some(&[lo, hi]) if lo.is_finite() && hi.is_finite() && lo < hi => Some((lo, hi)),
            Some(v) => anyhow::bail!(
                "--use-range-c {}: takes MIN,MAX in °C, MIN below MAX",
                v.iter().map(f64::to_string).collect::<Vec<_>>().join(",")
            ),
        };
        if let Some(r) = self.use_rate_c_per_min {
            anyhow::ensure!(r.is_finite() && r > 0.0, "--use-rate-c-per-min {r}: must be above 0");
        }
        Ok(InUse {
            range_c,
            max_rate_c_per_min: self.use_rate_c_per_min,
        })
    }
}

/// Centre counts the firmware holds: 1 … [`rbf_core::MAX_CENTERS`].
fn centers_parser() -> RangedU64ValueParser<usize> {
    RangedU64ValueParser::<usize>::new().range(1..=rbf_core::MAX_CENTERS as u64)
}

/// A multi-point input by its column names: `temp_c` or `temp_c-temp_e`.
fn parse_probe(text: &str) -> Result<Probe, String> {
    let index = |name: &str| {
        rbf_core::record::column::THERMOMETERS
            .iter()
            .position(|t| *t == name.trim())
            .map(|i| i as u8)
            .ok_or_else(|| format!("{name:?} is not one of temp_a … temp_h"))
    };
    let probe = match text.split_once('-') {
        Some((hot, cold)) => Probe::Gradient(index(hot)?, index(cold)?),
        None => Probe::Temp(index(text)?),
    };
    if probe.is_valid() {
        Ok(probe)
    } else {
        Err(format!("{text:?}: a gradient needs two different thermometers"))
    }
}

/// Refuses an input named twice in `--inputs`, a gradient in either order
/// included (`temp_a-temp_b` and `temp_b-temp_a` carry the same information).
fn check_distinct_inputs(inputs: &[Probe]) -> anyhow::Result<()> {
    let key = |p: &Probe| match *p {
        Probe::Temp(i) => (i, i),
        Probe::Gradient(i, j) => (i.min(j), i.max(j)),
    };
    let name = |i: u8| {
        rbf_core::record::column::THERMOMETERS
            .get(usize::from(i))
            .copied()
            .unwrap_or("?")
    };
    for (k, p) in inputs.iter().enumerate() {
        if let Some(q) = inputs[..k].iter().find(|q| key(q) == key(p)) {
            let show = |p: &Probe| match *p {
                Probe::Temp(i) => name(i).to_owned(),
                Probe::Gradient(i, j) => format!("{}-{}", name(i), name(j)),
            };
            anyhow::bail!(
                "--inputs names {} and {}: the same input twice; name each temperature or gradient once",
                show(q),
                show(p)
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use clap::{Parser, ValueEnum};

    use super::*;

    /// `trainer fit`'s arguments alone, for parsing tests.
    #[derive(clap::Parser)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    fn options(extra: &[&str]) -> anyhow::Result<FitOptions> {
        let argv = ["fit", "run.csv", "-o", "model.bin"]
            .into_iter()
            .chain(extra.iter().copied());
        Cli::try_parse_from(argv)?.args.fit_options()
    }

    #[test]
    fn each_method_and_feature_set_parses_to_its_own_variant() {
        let method = |extra: &[&str]| options(extra).unwrap().method;
        assert_eq!(method(&[]), Method::default());
        assert!(matches!(
            method(&["--features", "lag-bank"]),
            Method::LagBank(LagBankOptions {
                structure_choice: false,
                ..
            })
        ));
        assert_eq!(method(&["--features", "response-bank"]), Method::ResponseBank);
        assert!(matches!(
            method(&["--features", "paper", "--centers", "8"]),
            Method::Rbf {
                inputs: RbfInputs::Paper,
                search: RbfSearch {
                    centers: CenterBudget::Fixed(8),
                    ..
                }
            }
        ));
        assert!(matches!(
            method(&["--features", "multiscale-validated", "--dt-window-s", "60"]),
            Method::MultiscaleValidated(RbfSearch { rate_windows_s, .. }) if rate_windows_s == [60.0]
        ));
        assert_eq!(method(&["--method", "poly3"]), Method::Poly3);
        assert!(matches!(
            method(&["--method", "svr-pso", "--select-top", "3", "--max-centers", "12"]),
            Method::SvrPso(SvrOptions {
                centers: CenterBudget::UpTo(12),
                inputs: SvrInputs::Rule(trainer::dataset::gradients::Selection::Top(3)),
                ..
            })
        ));
        // The name `--json` reports is the --method given.
        for m in MethodArg::value_variants() {
            let name = m.to_possible_value().unwrap().get_name().to_owned();
            assert_eq!(
                method(&["--method", &name]).name().to_lowercase(),
                name.replace('-', "")
            );
        }
    }

    #[test]
    fn options_a_method_would_ignore_are_refused_where_they_are_parsed() {
        let refused = |extra: &[&str]| format!("{:#}", options(extra).unwrap_err());
        assert!(refused(&["--dt-window-s", "60"]).contains("--dt-window-s would be ignored"));
        assert!(refused(&["--features", "paper", "--dt-window-s", "90000"]).contains("must be 0 … 86400 s"));
        assert!(refused(&["--inputs", "temp_a"]).contains("--inputs would be ignored"));
        assert!(refused(&["--centers", "4", "--max-centers", "8"]).contains("give one of them"));
        assert!(
            refused(&["--method", "poly3", "--centers", "4"]).contains("--centers and --max-centers would be ignored")
        );
        assert!(
            refused(&["--features", "response-bank", "--max-centers", "4"])
                .contains("--centers and --max-centers would be ignored")
        );
    }

    #[test]
    fn probes_are_read_by_column_name() {
        assert!(matches!(parse_probe("temp_c"), Ok(Probe::Temp(2))));
        assert!(matches!(parse_probe("temp_a-temp_h"), Ok(Probe::Gradient(0, 7))));
        assert!(parse_probe("temp_z").unwrap_err().contains("not one of temp_a"));
        assert!(parse_probe("temp_b-temp_b").unwrap_err().contains("two different"));
    }
}

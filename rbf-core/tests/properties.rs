//! Properties of rbf-core over generated inputs (proptest):
//! - whatever the samples (finite or not, gaps, faults), every sample yields
//!   a finite bias and a compensated rate that is finite or flagged;
//! - every valid model survives blob encode → decode unchanged, bytes too;
//! - every single-bit flip of a blob is refused;
//!
//! the models drawn include thermal lag banks of every filter count.

use proptest::prelude::*;
use rbf_core::blob::{self, MAX_BLOB_LEN};
use rbf_core::lag_bank::{BANK_FILTERS, LagBank, MAX_STATIC_DEGREE};
use rbf_core::model::{DeployedRbf, ModelBody};
use rbf_core::poly::Poly3;
use rbf_core::rbf::RbfParams;
use rbf_core::{
    Compensator, CompensatorConfig, FeatureConfig, FeatureSet, Flags, GyroSample, MAX_CENTERS, Model, ModelInfo,
};

/// Any f32, weighted towards the hostile ones.
fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => -80.0f32..180.0,
        1 => any::<u32>().prop_map(f32::from_bits),
        1 => prop::sample::select(vec![
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.0,
            -0.0,
            f32::MAX,
            f32::MIN,
            f32::MIN_POSITIVE
        ]),
    ]
}

fn feature_config() -> impl Strategy<Value = FeatureConfig> {
    let window = prop_oneof![Just(0.0f32), 0.5f32..600.0];
    let set = prop::sample::select(vec![
        FeatureSet::Temp,
        FeatureSet::TempRate,
        FeatureSet::TempRateProduct,
        FeatureSet::MultiScale,
        FeatureSet::MultiScaleSecondOrder,
        FeatureSet::MultiScaleLagged { coil_lag_min: 25 },
    ]);
    let seed_sets = (set, window).prop_map(|(set, w)| match set {
        set if set.is_multiscale() => FeatureConfig::multiscale(set, [w, 8.0 * w, 64.0 * w]),
        _ => FeatureConfig::single(set, w),
    });
    prop_oneof![3 => seed_sets, 1 => lag_bank_config()]
}

/// A valid lag bank: 1–8 filters log-spaced from `fastest_s` by `ratio`,
/// coil lags within one filter time constant, a Shupe gain, a static degree
/// and a covered range of T̂.
fn lag_bank_config() -> impl Strategy<Value = FeatureConfig> {
    (
        1usize..=BANK_FILTERS,
        1.0f32..60.0,
        2.0f32..4.0,
        prop::array::uniform8(-1.0f32..1.0),
        -0.01f32..0.01,
        1u8..=MAX_STATIC_DEGREE,
        -40.0f32..20.0,
        1.0f32..80.0,
    )
        .prop_filter_map("refused bank", |(n, fastest_s, ratio, lag, gain, degree, lo, span)| {
            let taus: Vec<f32> = (0..n).map(|k| fastest_s * ratio.powi(k as i32)).collect();
            let mut bank = LagBank::plain(&taus, lo + 0.5 * span)?;
            for k in 0..n {
                bank.coil_lag_min[k] = lag[k] * taus[k] / 60.0;
            }
            bank.gain_per_c = gain;
            bank.static_degree = degree;
            (bank.coil_min_c, bank.coil_max_c) = (lo, lo + span);
            bank.is_valid().then(|| FeatureConfig::lag_bank(bank))
        })
}

/// A valid RBF model of configuration `cfg` with `k` centres, its parameters
/// drawn by a xorshift generator from `seed`; `None` if the draw is refused.
fn rbf_model(cfg: FeatureConfig, k: usize, seed: u64) -> Option<Model> {
    let d = cfg.dims();
    let mut state = seed | 1;
    let mut next = |lo: f32, hi: f32| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        lo + (hi - lo) * ((state >> 40) as f32 / (1u64 << 24) as f32)
    };
    let m = 1 + (next(0.0, d as f32) as usize).min(d - 1);
    let ranges: Vec<(f32, f32)> = (0..d)
        .map(|_| {
            let lo = next(-50.0, 50.0);
            (lo, lo + next(0.0, 100.0))
        })
        .collect();
    let offset: Vec<f32> = ranges.iter().map(|(lo, hi)| 0.5 * (lo + hi)).collect();
    let scale: Vec<f32> = (0..d).map(|_| next(0.01, 100.0)).collect();
    let centers: Vec<f32> = (0..k * m).map(|_| next(-3.0, 3.0)).collect();
    let widths: Vec<f32> = (0..k).map(|_| next(0.05, 10.0)).collect();
    let weights: Vec<f32> = (0..k).map(|_| next(-1e3, 1e3)).collect();
    let linear: Vec<f32> = if next(0.0, 1.0) < 0.5 {
        vec![]
    } else {
        (0..d).map(|_| next(-100.0, 100.0)).collect()
    };
    let net = DeployedRbf::new(&RbfParams {
        offset: &offset,
        scale: &scale,
        kernel_inputs: m,
        centers: &centers,
        widths: &widths,
        weights: &weights,
        linear: &linear,
        constant: next(-1e3, 1e3),
    })
    .ok()?;
    Model::new(cfg, &ranges, ModelBody::Rbf(net), ModelInfo::default()).ok()
}

/// Valid models of every kind and shape the firmware holds.
fn model() -> impl Strategy<Value = Model> {
    let rbf = (feature_config(), 0usize..=MAX_CENTERS, any::<u64>())
        .prop_filter_map("refused draw", |(cfg, k, seed)| rbf_model(cfg, k, seed));
    let poly = (
        -20.0f32..60.0,
        prop::array::uniform4(-1.0f32..1.0),
        -50.0f32..50.0,
        0.0f32..100.0,
    )
        .prop_filter_map("refused draw", |(t_ref, c, lo, span)| {
            let body = ModelBody::Poly3(Poly3::new(t_ref, [c[0] * 100.0, c[1], c[2] * 1e-2, c[3] * 1e-4]).ok()?);
            let cfg = FeatureConfig::single(FeatureSet::Temp, 0.0);
            Model::new(cfg, &[(lo, lo + span)], body, ModelInfo::default()).ok()
        });
    prop_oneof![3 => rbf, 1 => poly]
}

fn sample() -> impl Strategy<Value = GyroSample> {
    let dt = prop_oneof![8 => Just(1.0f32), 1 => 0.0f32..5.0, 1 => any_f32()];
    let temp = prop_oneof![
        8 => (-40.0f32..60.0).prop_map(Some),
        1 => Just(None),
        1 => any_f32().prop_map(Some),
    ];
    (dt, any_f32(), temp).prop_map(|(dt_s, rate_dph, temp_c)| GyroSample::new(dt_s, rate_dph, temp_c))
}

fn encode(model: &Model) -> Vec<u8> {
    let mut buf = vec![0u8; MAX_BLOB_LEN];
    let len = blob::encode(model, &mut buf).expect("every valid model encodes");
    buf.truncate(len);
    buf
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn every_sample_gives_a_finite_or_flagged_output(
        model in prop::option::weighted(0.9, model()),
        samples in prop::collection::vec(sample(), 1..400),
    ) {
        let config = CompensatorConfig::for_sample_rate(1.0);
        let mut compensator = Compensator::new();
        for s in &samples {
            let out = compensator.process(model.as_ref(), &config, s);
            prop_assert!(out.bias_dph.is_finite(), "bias {} for {s:?}", out.bias_dph);
            prop_assert!(
                out.rate_comp_dph.is_finite() || out.flags.contains(Flags::RATE_INVALID),
                "unflagged non-finite output {out:?} for {s:?}"
            );
            prop_assert!(
                out.temp_c.is_finite()
                    || out.flags.contains(Flags::TEMP_SENSOR_FAULT)
                    || out.flags.contains(Flags::NO_VALID_MODEL),
                "unflagged missing temperature {out:?} for {s:?}"
            );
            if model.is_none() {
                prop_assert!(out.flags.contains(Flags::NO_VALID_MODEL));
            }
        }
    }

    #[test]
    fn blobs_survive_encode_decode_unchanged(model in model()) {
        let bytes = encode(&model);
        let decoded = blob::decode(&bytes).expect("an encoded model decodes");
        prop_assert_eq!(&decoded.model, &model);
        prop_assert_eq!(decoded.len, bytes.len());
        prop_assert_eq!(encode(&decoded.model), bytes);
    }

    #[test]
    fn every_single_bit_flip_of_a_blob_is_refused(model in model()) {
        let bytes = encode(&model);
        for bit in 0..bytes.len() * 8 {
            let mut flipped = bytes.clone();
            flipped[bit / 8] ^= 1 << (bit % 8);
            prop_assert!(blob::decode(&flipped).is_err(), "flip of bit {bit} accepted");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 20_000, ..ProptestConfig::default() })]

    #[test]
    fn the_fast_number_parser_agrees_with_core_on_every_input(
        text in prop_oneof![
            4 => "[+-]?[0-9]{0,20}(\\.[0-9]{0,25})?",
            1 => "[+-]?[0-9]{1,3}(\\.[0-9]{1,8})?[eE][+-]?[0-9]{1,3}",
            1 => "[0-9a-zA-Z.+\\- ]{0,12}",
            1 => prop::sample::select(vec![
                "9007199254740992".to_owned(), "9007199254740993".to_owned(), "0.1".to_owned(), "-0".to_owned(),
                "-0.0".to_owned(), ".5".to_owned(), "5.".to_owned(), ".".to_owned(), "".to_owned(), "+".to_owned(),
                "inf".to_owned(), "NaN".to_owned(), "1e400".to_owned(), "0.30000000000000004".to_owned(),
            ]),
        ],
    ) {
        let ours = rbf_core::record::parse_f64(&text).map(f64::to_bits).ok();
        let core = text.parse::<f64>().map(f64::to_bits).ok();
        prop_assert_eq!(ours, core, "{:?}", text);
    }
}

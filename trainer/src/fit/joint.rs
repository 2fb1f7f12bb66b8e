//! The joint fit of a multi-axis IMU whose axes read one thermometer: one
//! model basis (the structure a single-axis fit chose: features,
//! normalisation, centres, width), and per axis only the output layer
//! (Gaussian weights, linear terms, constant), refitted by ridge least
//! squares on that axis's own block means with the basis's ridge.
//! The result is a [`SharedAxisModels`], whose step evaluates the kernels
//! once for every axis (docs/blob-format.md, "Shared-basis blobs").

use nalgebra::DVector;
use rbf_core::axis::Axis;
use rbf_core::model::ModelBody;
use rbf_core::shared_basis::{OutputLayer, SharedAxisModels};
use rbf_core::{MAX_INPUTS, Model};

use super::linalg::{FeatureRow, GramStats, InputShape, design, ridge_solve};
use crate::dataset::RunSet;

/// The shared-basis model of `basis`'s structure with each axis's output
/// layer refitted on that axis's training runs (`axes`: the axis and its
/// runs, read through the basis's feature configuration, `block_s` long
/// block means) by ridge least squares at `ridge`. Refused, with the
/// reason, when the basis is not a network of one shared width or a
/// system is singular.
pub fn refit_layers<T: RunSet + ?Sized>(
    basis: &Model,
    ridge: f64,
    axes: &[(Axis, &T)],
    block_s: f64,
) -> anyhow::Result<SharedAxisModels> {
    let ModelBody::Rbf(net) = basis.body() else {
        anyhow::bail!(
            "a joint model needs a Gaussian RBF basis, the fit chose a {}",
            basis.kind().name()
        );
    };
    let width = match net.widths() {
        [first, rest @ ..] if rest.iter().all(|w| w.to_bits() == first.to_bits()) => f64::from(*first),
        [] => 1.0,
        _ => anyhow::bail!("a joint model needs one Gaussian width shared by the centres"),
    };
    let dims = basis.features().dims();
    let shape = InputShape {
        dims,
        kernel: net.kernel_inputs(),
    };
    let centers: Vec<FeatureRow> = (0..net.centers_used())
        .map(|j| {
            let mut row = [0.0; MAX_INPUTS];
            for (r, c) in row.iter_mut().zip(net.center(j)) {
                *r = f64::from(*c);
            }
            row
        })
        .collect();
    let offset: Vec<f64> = net.offset().iter().map(|&v| f64::from(v)).collect();
    let scale: Vec<f64> = net.scale().iter().map(|&v| f64::from(v)).collect();
    let first = axes
        .first()
        .ok_or_else(|| anyhow::anyhow!("a joint model needs at least one axis"))?;
    let mut shared = SharedAxisModels::from_models(&[(first.0, basis)])
        .map_err(|e| anyhow::anyhow!("the basis is not deployable: {e}"))?;
    for &(axis, runs) in axes {
        let blocks = runs.block_means(basis.features(), block_s)?;
        let z: Vec<FeatureRow> = blocks
            .x
            .iter()
            .map(|x| {
                let mut z = [0.0; MAX_INPUTS];
                for i in 0..dims {
                    z[i] = (x[i] - offset[i]) / scale[i];
                }
                z
            })
            .collect();
        let rows: Vec<usize> = (0..blocks.len()).collect();
        let a = design(&z, &rows, shape, &centers, width);
        let stats = GramStats::new(&a, &DVector::from_column_slice(&blocks.y));
        let w = ridge_solve(&stats, 1 + dims + centers.len(), ridge)
            .ok_or_else(|| anyhow::anyhow!("axis {}: the output-layer system is singular", axis.name()))?;
        let to_f32 = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
        let linear = if net.linear().is_empty() {
            Vec::new()
        } else {
            to_f32(&w.as_slice()[1..1 + dims])
        };
        let weights = to_f32(&w.as_slice()[1 + dims..]);
        shared
            .assign_layer(
                axis,
                &OutputLayer {
                    weights: &weights,
                    linear: &linear,
                    constant: w[0] as f32,
                },
            )
            .map_err(|e| anyhow::anyhow!("axis {}: the refitted layer is not deployable: {e}", axis.name()))?;
    }
    Ok(shared)
}

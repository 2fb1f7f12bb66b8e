//! The simulated gyro's parameters: its thermal plant and bias model, read
//! from JSON over the documented defaults.

use super::{gyro, plant};

/// The simulated gyro: its thermal network and its bias and noise. Read from
/// `trainer simulate --params FILE.json` (any field left out keeps the
/// documented default, or the `--unit` draw's value), e.g. `{"plant":
/// {"tau_top_s": 2400}, "gyro": {"axial_gradient_dph_per_c": 0.05}}`.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SimParams {
    /// Time constants and couplings of the thermal network.
    pub plant: plant::PlantParams,
    /// Bias and noise.
    pub gyro: gyro::GyroParams,
}

impl SimParams {
    /// Why these parameters cannot be simulated, if they cannot.
    pub fn check(&self) -> Result<(), String> {
        self.plant.check().and_then(|()| self.gyro.check())?;
        if self.gyro.shupe_layer_weights.len() != self.plant.coil_layers {
            return Err(format!(
                "gyro.shupe_layer_weights has {} weights, the coil {} layers (plant.coil_layers): give one per layer",
                self.gyro.shupe_layer_weights.len(),
                self.plant.coil_layers
            ));
        }
        Ok(())
    }

    /// These parameters with the fields of the JSON object `json` (the text
    /// of a `--params` file) put over them; nested objects (`plant`, `gyro`,
    /// `plant.hub`) field by field, any other value whole. Syntax errors and
    /// unknown fields give the line and column; the result is checked.
    pub fn overridden(&self, json: &str) -> Result<SimParams, ParamsError> {
        // Parsing alone first: it places syntax errors and unknown fields.
        serde_json::from_str::<SimParams>(json).map_err(|e| {
            let message = e.to_string();
            // serde_json appends the place; the caller leads with it instead.
            let message = message.split(" at line ").next().unwrap_or(&message).to_owned();
            ParamsError::Syntax {
                line: e.line(),
                column: e.column(),
                message,
            }
        })?;
        let overrides: serde_json::Value =
            serde_json::from_str(json).map_err(|e| ParamsError::Invalid(e.to_string()))?;
        let mut merged = serde_json::to_value(self).map_err(|e| ParamsError::Invalid(e.to_string()))?;
        merge(&mut merged, overrides);
        let params: SimParams = serde_json::from_value(merged).map_err(|e| ParamsError::Invalid(e.to_string()))?;
        params.check().map_err(ParamsError::Invalid)?;
        Ok(params)
    }
}

/// Why a `--params` file cannot be used.
#[derive(Debug, thiserror::Error)]
pub enum ParamsError {
    /// Bad JSON or an unknown field, at a place.
    #[error("{line}:{column}: {message}")]
    Syntax {
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// Parameters that cannot be simulated.
    #[error("{0}")]
    Invalid(String),
}

/// Puts `over` over `base`: objects field by field, anything else whole.
fn merge(base: &mut serde_json::Value, over: serde_json::Value) {
    match (base, over) {
        (serde_json::Value::Object(base), serde_json::Value::Object(over)) => {
            for (key, value) in over {
                match base.get_mut(&key) {
                    Some(slot) => merge(slot, value),
                    None => {
                        base.insert(key, value);
                    }
                }
            }
        }
        (slot, value) => *slot = value,
    }
}

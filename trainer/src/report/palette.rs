//! The report's colours, one meaning each on every plot: the same grey is
//! always "outside the training range", never a data series; "before" is
//! always red and "after" always blue.

use plotters::style::RGBColor;

/// Uncompensated data: the raw rate, the Allan curve and settled bias before compensation.
pub(super) const BEFORE: RGBColor = RGBColor(200, 60, 40);
/// Compensated data: the rate, the Allan curve and settled bias after compensation.
pub(super) const AFTER: RGBColor = RGBColor(30, 90, 200);
/// The loop temperature (a right-hand axis).
pub(super) const TEMPERATURE: RGBColor = RGBColor(120, 80, 160);
/// Samples taken while the loop heated.
pub(super) const HEATING: RGBColor = RGBColor(230, 120, 30);
/// Samples taken while the loop cooled.
pub(super) const COOLING: RGBColor = RGBColor(20, 160, 180);
/// Samples taken while the loop held its temperature.
pub(super) const STEADY: RGBColor = RGBColor(40, 150, 70);
/// What lies outside the training data (samples, surface cells): only this.
pub(super) const OUTSIDE_TRAINING: RGBColor = RGBColor(170, 170, 170);
/// Fill of the bias surface's cells that no sample reached (hatched in
/// [`OUTSIDE_TRAINING`] over it): no colour, so none reads as a bias.
pub(super) const MASKED: RGBColor = RGBColor(232, 232, 232);
/// Compensated samples whose inputs were clamped to the training range (flag 1).
pub(super) const CLAMPED: RGBColor = RGBColor(200, 0, 160);
/// Read-off guides (the τ^−½ ARW line, the τ^+½ guide).
pub(super) const GUIDE: RGBColor = RGBColor(90, 90, 90);
/// The bias-instability floor line.
pub(super) const FLOOR: RGBColor = RGBColor(230, 140, 20);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_meaning_has_its_own_colour() {
        let all = [
            BEFORE,
            AFTER,
            TEMPERATURE,
            HEATING,
            COOLING,
            STEADY,
            OUTSIDE_TRAINING,
            MASKED,
            CLAMPED,
            GUIDE,
            FLOOR,
        ];
        for (i, a) in all.iter().enumerate() {
            for b in &all[i + 1..] {
                assert_ne!((a.0, a.1, a.2), (b.0, b.1, b.2));
            }
        }
    }
}

//! The sensitive axes of a multi-axis IMU, as runs, frames and model
//! blobs number and name them.

/// Most gyro axes a run or a model blob carries.
pub const MAX_AXES: usize = 3;

/// One sensitive axis of a multi-axis IMU.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Axis {
    /// The x axis.
    X,
    /// The y axis.
    Y,
    /// The z axis.
    Z,
}

impl Axis {
    /// Every axis, in column and blob order.
    pub const ALL: [Axis; MAX_AXES] = [Axis::X, Axis::Y, Axis::Z];

    /// 0 for x, 1 for y, 2 for z.
    pub const fn index(self) -> usize {
        self as usize
    }

    /// The axis of index 0, 1 or 2.
    pub const fn from_index(index: usize) -> Option<Axis> {
        match index {
            0 => Some(Axis::X),
            1 => Some(Axis::Y),
            2 => Some(Axis::Z),
            _ => None,
        }
    }

    /// `x`, `y` or `z`: the letter in the column names.
    pub const fn name(self) -> &'static str {
        match self {
            Axis::X => "x",
            Axis::Y => "y",
            Axis::Z => "z",
        }
    }

    /// The axis named `x`, `y` or `z`.
    pub fn from_name(name: &str) -> Option<Axis> {
        Axis::ALL.into_iter().find(|a| a.name() == name)
    }

    /// The axis's rate column, e.g. `rate_x_dph` (the recorded-run format's).
    pub const fn rate_column(self) -> &'static str {
        match self {
            Axis::X => "rate_x_dph",
            Axis::Y => "rate_y_dph",
            Axis::Z => "rate_z_dph",
        }
    }
}
/// A set of axes, as a multi-axis blob's header and the model holders keep it: bit 0 x,
/// bit 1 y, bit 2 z.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct AxisSet(u8);

impl AxisSet {
    /// No axis.
    pub const EMPTY: AxisSet = AxisSet(0);

    /// The set of the bits of `bits` (a header's axis mask; bits above z are kept, so a
    /// reader can refuse them).
    pub const fn from_bits(bits: u8) -> AxisSet {
        AxisSet(bits)
    }

    /// The set as a bit mask (bit 0 = x).
    pub const fn bits(self) -> u8 {
        self.0
    }

    /// True when `axis` is in the set.
    pub const fn contains(self, axis: Axis) -> bool {
        self.0 & (1 << axis.index()) != 0
    }

    /// True when no axis is in the set.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// Adds `axis`.
    pub fn insert(&mut self, axis: Axis) {
        self.0 |= 1 << axis.index();
    }

    /// The axes in the set, x first.
    pub fn iter(self) -> impl Iterator<Item = Axis> {
        Axis::ALL.into_iter().filter(move |a| self.contains(*a))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_axis_set_holds_what_was_inserted_and_lists_it_x_first() {
        let mut set = AxisSet::EMPTY;
        assert!(set.is_empty());
        set.insert(Axis::Z);
        set.insert(Axis::X);
        set.insert(Axis::Z);
        assert_eq!(set.bits(), 0b101);
        assert!(set.contains(Axis::X) && !set.contains(Axis::Y) && set.contains(Axis::Z));
        let mut axes = set.iter();
        assert_eq!(
            (axes.next(), axes.next(), axes.next()),
            (Some(Axis::X), Some(Axis::Z), None)
        );
        assert_eq!(
            AxisSet::from_bits(0b1000).iter().next(),
            None,
            "bits above z name no axis"
        );
    }
}

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

//! The thermometers of a run or a model: `temp_a` … `temp_h`, by index, and
//! sets of them ([`ThermometerSet`]), as a run's columns provide them and a
//! model's inputs read them.

/// Thermometers a multi-point model can read: `temp_a` … `temp_h`.
pub const THERMOMETERS: usize = 8;
/// Index of the fiber-loop thermometer (`temp_c`) among [`THERMOMETERS`]:
/// the one single-point feature sets read.
pub const LOOP_THERMOMETER: usize = 2;

/// The letter of thermometer `i` in its column name (`temp_a` … `temp_h`).
pub const fn thermometer_letter(i: u8) -> char {
    (b'a' + i) as char
}

/// A set of thermometers by index: bit i is thermometer i (bit 0 `temp_a`,
/// bit 2 the fiber loop's `temp_c`). What a run's columns provide, what a
/// model's inputs read, what the firmware asks its sensors for.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct ThermometerSet(u8);

impl ThermometerSet {
    /// No thermometer.
    pub const EMPTY: ThermometerSet = ThermometerSet(0);
    /// Every one of the [`THERMOMETERS`].
    pub const ALL: ThermometerSet = ThermometerSet(u8::MAX);
    /// The fiber-loop thermometer alone: what the single-point feature sets read.
    pub const LOOP: ThermometerSet = ThermometerSet::of(LOOP_THERMOMETER as u8);

    /// Thermometer `i` alone (no thermometer past the eighth).
    pub const fn of(i: u8) -> ThermometerSet {
        ThermometerSet(if (i as usize) < THERMOMETERS { 1 << i } else { 0 })
    }

    /// The set of the bits of `bits` (bit i = thermometer i).
    pub const fn from_bits(bits: u8) -> ThermometerSet {
        ThermometerSet(bits)
    }

    /// The set as a bit mask (bit i = thermometer i).
    pub const fn bits(self) -> u8 {
        self.0
    }

    /// True when thermometer `i` is in the set.
    pub const fn contains(self, i: usize) -> bool {
        i < THERMOMETERS && self.0 & (1 << i) != 0
    }

    /// How many thermometers the set holds.
    pub const fn len(self) -> usize {
        self.0.count_ones() as usize
    }

    /// True when no thermometer is in the set.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The thermometers in either set.
    pub const fn union(self, other: ThermometerSet) -> ThermometerSet {
        ThermometerSet(self.0 | other.0)
    }

    /// The thermometers in both sets.
    pub const fn intersection(self, other: ThermometerSet) -> ThermometerSet {
        ThermometerSet(self.0 & other.0)
    }

    /// The thermometers of this set that `other` lacks.
    pub const fn difference(self, other: ThermometerSet) -> ThermometerSet {
        ThermometerSet(self.0 & !other.0)
    }

    /// True when every thermometer of this set is in `other`.
    pub const fn is_subset(self, other: ThermometerSet) -> bool {
        self.difference(other).is_empty()
    }

    /// Adds thermometer `i` (nothing past the eighth).
    pub fn insert(&mut self, i: usize) {
        if i < THERMOMETERS {
            self.0 |= 1 << i;
        }
    }

    /// The indices of the thermometers in the set, lowest first.
    pub fn iter(self) -> impl Iterator<Item = usize> {
        (0..THERMOMETERS).filter(move |&i| self.contains(i))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_thermometer_set_holds_what_was_inserted_and_lists_it_lowest_first() {
        let mut set = ThermometerSet::EMPTY;
        assert!(set.is_empty());
        set.insert(7);
        set.insert(LOOP_THERMOMETER);
        set.insert(THERMOMETERS);
        assert_eq!((set.bits(), set.len()), (0b1000_0100, 2));
        assert!(set.contains(LOOP_THERMOMETER) && !set.contains(0) && !set.contains(THERMOMETERS));
        assert_eq!(set.iter().collect::<Vec<_>>(), [LOOP_THERMOMETER, 7]);
        assert_eq!(ThermometerSet::of(THERMOMETERS as u8), ThermometerSet::EMPTY);
    }

    #[test]
    fn set_operations_follow_the_bits() {
        let a = ThermometerSet::from_bits(0b0110);
        let b = ThermometerSet::from_bits(0b0011);
        assert_eq!(a.union(b).bits(), 0b0111);
        assert_eq!(a.intersection(b).bits(), 0b0010);
        assert_eq!(a.difference(b).bits(), 0b0100);
        assert!(ThermometerSet::LOOP.is_subset(a) && !a.is_subset(b));
        assert!(a.is_subset(ThermometerSet::ALL));
    }
}

//! The independent watchdog's period, derived from what it must outlast.
//!
//! The IWDG counts the LSI oscillator, whose frequency the STM32F405
//! datasheet gives as 17 … 47 kHz (32 kHz typical): a period must be
//! computed at the fastest LSI to be sure it outlasts a wait, and it may be
//! as long as at the slowest. The board feeds it once per sample; a model
//! install switches to [`install_setting`] around the flash erase (the CPU
//! stalls for the whole erase of a 128 KiB sector, up to
//! [`SECTOR_ERASE_WORST_MS`], interrupts and watchdog feeds included).

/// Fastest LSI the datasheet allows, Hz.
pub const LSI_FASTEST_HZ: u32 = 47_000;
/// Slowest LSI the datasheet allows, Hz.
pub const LSI_SLOWEST_HZ: u32 = 17_000;
/// Worst-case erase time of a 128 KiB sector (STM32F405 datasheet, the
/// slowest parallelism), ms.
pub const SECTOR_ERASE_WORST_MS: u32 = 4000;
/// Margin above the erase for the program and verify of the blob and record, ms.
pub const INSTALL_MARGIN_MS: u32 = 500;
/// Shortest period of the running watchdog, ms (at the fastest LSI): a loop
/// that processes no sample for this long is hung.
pub const RUNNING_MIN_MS: u32 = 2000;

/// The watchdog the board feeds.
pub trait Watchdog {
    /// Restarts the countdown.
    fn feed(&mut self);
    /// Changes the period (and feeds); false if the watchdog did not take it in time.
    fn set_period(&mut self, setting: IwdgSetting) -> bool;
}

/// Prescaler and reload of the IWDG (RM0090 §21: the counter runs at
/// LSI / (4 · 2^`prescaler_code`) and resets the chip after `reload` + 1 counts).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IwdgSetting {
    /// PR register: 0 = ÷4 … 6 = ÷256.
    pub prescaler_code: u8,
    /// RLR register, ≤ 0xFFF.
    pub reload: u16,
}

impl IwdgSetting {
    /// The LSI divider of this setting.
    pub const fn divider(&self) -> u32 {
        4 << self.prescaler_code
    }

    /// The period at an LSI of `lsi_hz`, µs.
    pub const fn period_us_at(&self, lsi_hz: u32) -> u64 {
        self.divider() as u64 * (self.reload as u64 + 1) * 1_000_000 / lsi_hz as u64
    }

    /// The finest setting whose period is at least `min_ms` even at the
    /// fastest LSI; `None` when the IWDG cannot count that long.
    pub const fn at_least_ms(min_ms: u32) -> Option<IwdgSetting> {
        let counts = (min_ms as u64 * LSI_FASTEST_HZ as u64).div_ceil(1000);
        let mut code = 0u8;
        while code <= 6 {
            let divider = 4u64 << code;
            let reload = counts.div_ceil(divider);
            if reload <= 0x1000 {
                // `reload` counts: RLR = reload − 1 (≥ 0).
                let rlr = if reload == 0 { 0 } else { reload - 1 };
                return Some(IwdgSetting {
                    prescaler_code: code,
                    reload: rlr as u16,
                });
            }
            code += 1;
        }
        None
    }
}

/// The period while samples run: at least [`RUNNING_MIN_MS`] at the fastest LSI.
pub const fn running_setting() -> IwdgSetting {
    match IwdgSetting::at_least_ms(RUNNING_MIN_MS) {
        Some(s) => s,
        None => IwdgSetting {
            prescaler_code: 6,
            reload: 0xFFF,
        },
    }
}

/// The period around a model install: the worst-case sector erase plus
/// [`INSTALL_MARGIN_MS`], at the fastest LSI.
pub const fn install_setting() -> IwdgSetting {
    match IwdgSetting::at_least_ms(SECTOR_ERASE_WORST_MS + INSTALL_MARGIN_MS) {
        Some(s) => s,
        None => IwdgSetting {
            prescaler_code: 6,
            reload: 0xFFF,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_install_period_outlasts_the_worst_erase_at_the_fastest_lsi_and_is_finite_at_the_slowest() {
        let s = install_setting();
        assert!(s.reload <= 0xFFF && s.prescaler_code <= 6);
        let fastest_us = s.period_us_at(LSI_FASTEST_HZ);
        assert!(
            fastest_us >= u64::from(SECTOR_ERASE_WORST_MS + INSTALL_MARGIN_MS) * 1000,
            "{fastest_us}"
        );
        assert!(s.period_us_at(LSI_SLOWEST_HZ) < 16_000_000);
        let r = running_setting();
        assert!(r.period_us_at(LSI_FASTEST_HZ) >= u64::from(RUNNING_MIN_MS) * 1000);
        assert!(r.period_us_at(LSI_FASTEST_HZ) < fastest_us);
    }

    #[test]
    fn a_period_the_iwdg_cannot_count_is_refused() {
        assert_eq!(IwdgSetting::at_least_ms(60_000), None);
        assert_eq!(IwdgSetting::at_least_ms(1).map(|s| s.prescaler_code), Some(0));
    }
}

//! The health report as the board fills it: why it last reset (from its
//! fault record and RCC_CSR, [`reset_cause_at_boot`]) and its brown-out
//! setting ([`brown_out_flag`]). The report's layout, its encoder and the
//! host's decoder are the wire protocol's ([`gyro_wire::health`]), which
//! the board fills from its counters (`board::image`).

use gyro_wire::health::{BOARD_BROWN_OUT_BELOW_2V7, ResetCause};

use crate::fault::{FaultReason, FaultRecord};

/// RCC_CSR bit: low-power reset.
const CSR_LPWRRSTF: u32 = 1 << 31;
/// RCC_CSR bit: window watchdog reset.
const CSR_WWDGRSTF: u32 = 1 << 30;
/// RCC_CSR bit: independent watchdog reset.
const CSR_IWDGRSTF: u32 = 1 << 29;
/// RCC_CSR bit: software reset.
const CSR_SFTRSTF: u32 = 1 << 28;
/// RCC_CSR bit: power-on/power-down reset.
const CSR_PORRSTF: u32 = 1 << 27;
/// RCC_CSR bit: NRST pin reset (also set by every internal reset).
const CSR_PINRSTF: u32 = 1 << 26;
/// RCC_CSR bit: brown-out reset.
const CSR_BORRSTF: u32 = 1 << 25;

/// The cause of the last reset from the fault record (if one survived)
/// and RCC_CSR; the most specific one wins (every internal reset also
/// sets PINRSTF, a power-on also BORRSTF).
pub fn reset_cause_at_boot(record: Option<FaultRecord>, rcc_csr: u32) -> ResetCause {
    match record.map(|r| r.reason) {
        Some(FaultReason::Panic) => return ResetCause::Panic,
        Some(FaultReason::HardFault) => return ResetCause::HardFault,
        _ => {}
    }
    if rcc_csr & CSR_IWDGRSTF != 0 {
        ResetCause::Watchdog
    } else if rcc_csr & (CSR_WWDGRSTF | CSR_LPWRRSTF) != 0 {
        ResetCause::Other
    } else if rcc_csr & CSR_SFTRSTF != 0 {
        ResetCause::Software
    } else if rcc_csr & CSR_PORRSTF != 0 {
        ResetCause::PowerOn
    } else if rcc_csr & CSR_BORRSTF != 0 {
        ResetCause::BrownOut
    } else if rcc_csr & CSR_PINRSTF != 0 {
        ResetCause::Pin
    } else {
        ResetCause::Other
    }
}

/// FLASH_OPTCR's BOR_LEV field (bits 3:2; RM0090 §3.7.1: 00 level 3, 2.70 V;
/// 01 level 2; 10 level 1; 11 off, the factory setting). Named here, not
/// through the PAC, whose enumeration names the codes in reverse.
const OPTCR_BOR_LEV_SHIFT: u32 = 2;
const OPTCR_BOR_LEV_MASK: u32 = 0b11 << OPTCR_BOR_LEV_SHIFT;
/// BOR_LEV code of brown-out level 3 (reset below 2.70 V).
pub const BOR_LEVEL_3: u32 = 0b00;

/// The board flag [`BOARD_BROWN_OUT_BELOW_2V7`] for the option control
/// register `flash_optcr` as read at boot: set unless BOR_LEV is level 3.
pub const fn brown_out_flag(flash_optcr: u32) -> u32 {
    if (flash_optcr & OPTCR_BOR_LEV_MASK) >> OPTCR_BOR_LEV_SHIFT == BOR_LEVEL_3 {
        0
    } else {
        BOARD_BROWN_OUT_BELOW_2V7
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reset_cause_prefers_the_fault_record_then_the_most_specific_flag() {
        let hard = FaultRecord {
            reason: FaultReason::HardFault,
            pc: 1,
            lr: 2,
        };
        assert_eq!(reset_cause_at_boot(Some(hard), CSR_PINRSTF), ResetCause::HardFault);
        assert_eq!(
            reset_cause_at_boot(None, CSR_IWDGRSTF | CSR_PINRSTF),
            ResetCause::Watchdog
        );
        assert_eq!(
            reset_cause_at_boot(None, CSR_PORRSTF | CSR_BORRSTF | CSR_PINRSTF),
            ResetCause::PowerOn
        );
        assert_eq!(
            reset_cause_at_boot(None, CSR_BORRSTF | CSR_PINRSTF),
            ResetCause::BrownOut
        );
        assert_eq!(
            reset_cause_at_boot(None, CSR_SFTRSTF | CSR_PINRSTF),
            ResetCause::Software
        );
        assert_eq!(reset_cause_at_boot(None, CSR_PINRSTF), ResetCause::Pin);
    }

    #[test]
    fn only_brown_out_level_3_clears_the_flag_and_the_factory_option_bytes_set_it() {
        // RM0090 §3.7.1: OPTCR's reset value, BOR off.
        assert_eq!(brown_out_flag(0x0FFF_AAED), BOARD_BROWN_OUT_BELOW_2V7);
        assert_eq!(brown_out_flag(0x0FFF_AAE1), 0, "BOR_LEV = 00: level 3, 2.70 V");
        assert_eq!(brown_out_flag(0x0FFF_AAE5), BOARD_BROWN_OUT_BELOW_2V7, "level 2");
        assert_eq!(brown_out_flag(0x0FFF_AAE9), BOARD_BROWN_OUT_BELOW_2V7, "level 1");
    }
}

//! Proves from the flashed board image itself that it cannot panic: no
//! direct branch anywhere in its machine code (from `llvm-objdump`) goes to
//! the panic machinery (`core::panicking::panic_fmt`, the panic handler),
//! init included (the clock setup, the HAL constructors); and, in the call
//! graph of every direct branch between functions, none is reachable from
//! the board's loop (`run_forever`) and its interrupt and fault handlers,
//! nor does an indirect branch there hide one.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::path::Path;
use std::process::Command;

use anyhow::{Context, bail};

/// Functions the board runs after init: its loop and its handlers. Each
/// must be in the image (a check over nothing would pass).
const ROOTS: [&str; 5] = ["run_forever", "EXTI0", "USART1", "HardFault", "SysTick"];

/// Every panic goes through these (mangled names contain them).
const PANIC_ENTRIES: [&str; 3] = ["panic_fmt", "panic_nounwind", "rust_begin_unwind"];

/// A function of the image: start address (Thumb bit cleared), size, name.
#[derive(Clone, Debug)]
struct Function {
    start: u64,
    size: u64,
    name: String,
}

/// What the check found: functions reachable after init.
#[derive(Debug)]
pub struct Reach {
    /// Functions reachable from the roots, roots included.
    pub functions: usize,
}

/// Checks the ELF image at `elf` (see the module documentation).
pub fn check_board_image(elf: &Path) -> anyhow::Result<Reach> {
    let functions = functions(elf)?;
    let objdump = objdump()?;
    let out = Command::new(&objdump)
        .args(["-d", "--no-show-raw-insn"])
        .arg(elf)
        .output()
        .with_context(|| format!("cannot run {objdump}"))?;
    if !out.status.success() {
        bail!("{objdump} failed on {}", elf.display());
    }
    check_disassembly(&functions, &String::from_utf8_lossy(&out.stdout))
}

/// The call graph of `disassembly` over `functions`, searched from [`ROOTS`].
fn check_disassembly(functions: &[Function], disassembly: &str) -> anyhow::Result<Reach> {
    let owner = |addr: u64| {
        let i = functions.partition_point(|f| f.start <= addr).checked_sub(1)?;
        let f = &functions[i];
        (addr < f.start + f.size).then_some(i)
    };
    let is_panic = |f: usize| PANIC_ENTRIES.iter().any(|p| functions[f].name.contains(p));
    let mut edges: BTreeMap<usize, BTreeSet<usize>> = BTreeMap::new();
    let mut panic_sites: Vec<String> = Vec::new();
    let mut indirect: BTreeMap<usize, Vec<String>> = BTreeMap::new();
    for line in disassembly.lines() {
        let Some((addr, mnemonic, operands)) = parse_instruction(line) else {
            continue;
        };
        let Some(from) = owner(addr) else { continue };
        if matches!(mnemonic, "blx" | "bx") && !operands.starts_with("lr") {
            indirect
                .entry(from)
                .or_default()
                .push(format!("{addr:#x}: {mnemonic} {operands}"));
        } else if is_direct_branch(mnemonic) {
            let target = operands
                .split_whitespace()
                .find_map(|w| u64::from_str_radix(w.strip_prefix("0x")?, 16).ok());
            if let Some(to) = target.and_then(owner).filter(|to| *to != from) {
                edges.entry(from).or_default().insert(to);
                if is_panic(to) && !is_panic(from) {
                    panic_sites.push(format!("{addr:#x} in {}", functions[from].name));
                }
            }
        }
    }
    let roots: Vec<usize> = ROOTS
        .iter()
        .map(|root| {
            functions
                .iter()
                .position(|f| f.name == *root || f.name.contains(&format!("{}{root}", root.len())))
                .with_context(|| format!("the board image has no function {root}: the check would prove nothing"))
        })
        .collect::<anyhow::Result<_>>()?;
    // Breadth first, remembering who reached whom for the report.
    let mut parent: BTreeMap<usize, Option<usize>> = roots.iter().map(|r| (*r, None)).collect();
    let mut queue: VecDeque<usize> = roots.into_iter().collect();
    while let Some(f) = queue.pop_front() {
        for &g in edges.get(&f).into_iter().flatten() {
            if let std::collections::btree_map::Entry::Vacant(e) = parent.entry(g) {
                e.insert(Some(f));
                queue.push_back(g);
            }
        }
    }
    if let Some(&panic) = parent
        .keys()
        .find(|f| PANIC_ENTRIES.iter().any(|p| functions[**f].name.contains(p)))
    {
        let mut chain = vec![functions[panic].name.clone()];
        let mut at = parent.get(&panic).copied().flatten();
        while let Some(f) = at {
            chain.push(functions[f].name.clone());
            at = parent.get(&f).copied().flatten();
        }
        bail!(
            "a panic is reachable after init in the board image (docs/panic-free.md):\n  {}",
            chain.join("\n  called from ")
        );
    }
    // Then anywhere else: init too.
    if !panic_sites.is_empty() {
        bail!(
            "{} panic call sites in the board image (docs/panic-free.md):\n  {}",
            panic_sites.len(),
            panic_sites.join("\n  ")
        );
    }
    // Indirect branches (`blx rN`, `bx rN`): the graph cannot follow them.
    let indirect: Vec<String> = parent
        .keys()
        .filter_map(|f| {
            indirect
                .get(f)
                .map(|b| format!("{}: {}", functions[*f].name, b.join(", ")))
        })
        .collect();
    if !indirect.is_empty() {
        bail!(
            "indirect branches after init, which the panic check cannot follow:\n  {}",
            indirect.join("\n  ")
        );
    }
    Ok(Reach {
        functions: parent.len(),
    })
}

/// `  8001480:  bl  0x8003498 <sym> @ imm = #4` → (address, mnemonic, operands).
fn parse_instruction(line: &str) -> Option<(u64, &str, &str)> {
    let (addr, rest) = line.trim_start().split_once(':')?;
    let addr = u64::from_str_radix(addr, 16).ok()?;
    let rest = rest.trim_start();
    let (mnemonic, operands) = rest.split_once(char::is_whitespace).unwrap_or((rest, ""));
    Some((addr, mnemonic, operands.trim_start()))
}

/// B, BL, B<cond>, CBZ, CBNZ with an optional width suffix.
fn is_direct_branch(mnemonic: &str) -> bool {
    const CONDITIONS: [&str; 17] = [
        "", "eq", "ne", "hs", "cs", "lo", "cc", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt", "le",
    ];
    let base = mnemonic.trim_end_matches(".w").trim_end_matches(".n");
    if base == "cbz" || base == "cbnz" {
        return true;
    }
    let stem = base.strip_prefix("bl").or_else(|| base.strip_prefix('b'));
    stem.is_some_and(|c| CONDITIONS.contains(&c))
}

/// The image's functions, sorted by address.
fn functions(elf: &Path) -> anyhow::Result<Vec<Function>> {
    use object::{Object, ObjectSymbol, SymbolKind};
    let data = std::fs::read(elf).with_context(|| format!("{}: cannot read", elf.display()))?;
    let file = object::File::parse(&*data).with_context(|| format!("{}: not an ELF image", elf.display()))?;
    let mut functions: Vec<Function> = file
        .symbols()
        .filter(|s| s.kind() == SymbolKind::Text && s.size() > 0)
        .map(|s| Function {
            start: s.address() & !1,
            size: s.size(),
            name: s.name().unwrap_or("").to_owned(),
        })
        .collect();
    functions.sort_by_key(|f| f.start);
    Ok(functions)
}

/// llvm-objdump: from the rustup llvm-tools component, else on PATH.
fn objdump() -> anyhow::Result<String> {
    let sysroot = Command::new("rustc").args(["--print", "sysroot"]).output().ok();
    let host = Command::new("rustc").args(["--print", "host-tuple"]).output().ok();
    if let (Some(sysroot), Some(host)) = (sysroot, host) {
        let tool = Path::new(String::from_utf8_lossy(&sysroot.stdout).trim())
            .join("lib/rustlib")
            .join(String::from_utf8_lossy(&host.stdout).trim())
            .join("bin/llvm-objdump");
        if tool.exists() {
            return Ok(tool.display().to_string());
        }
    }
    if Command::new("llvm-objdump").arg("--version").output().is_ok() {
        return Ok("llvm-objdump".into());
    }
    bail!("llvm-objdump not found: `rustup component add llvm-tools` installs it")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f(start: u64, size: u64, name: &str) -> Function {
        Function {
            start,
            size,
            name: name.into(),
        }
    }

    fn image() -> Vec<Function> {
        vec![
            f(0x100, 0x10, "EXTI0"),
            f(0x110, 0x10, "USART1"),
            f(0x120, 0x10, "HardFault"),
            f(0x130, 0x10, "SysTick"),
            f(0x200, 0x20, "_ZN8firmware5board5image11run_forever17h0E"),
            f(0x300, 0x10, "_ZN4step17h1E"),
            f(0x400, 0x10, "_ZN4init17h2E"),
            f(0x500, 0x10, "_RNvNtCs0_4core9panicking9panic_fmt"),
        ]
    }

    #[test]
    fn a_panic_reached_from_the_loop_fails_naming_the_path() {
        let asm = "  200:  bl  0x300 <step>\n  302:  bne.w 0x500 <panic_fmt> @ imm = #4\n";
        let err = check_disassembly(&image(), asm).unwrap_err().to_string();
        assert!(
            err.contains("panic_fmt") && err.contains("4step") && err.contains("run_forever"),
            "{err}"
        );
    }

    #[test]
    fn a_panic_call_site_in_init_fails_too() {
        let asm = "  200:  bl  0x300 <step>\n  402:  bl  0x500 <panic_fmt>\n  104:  b.w 0x300 <step>\n";
        let err = check_disassembly(&image(), asm).unwrap_err().to_string();
        assert!(err.contains("1 panic call sites") && err.contains("4init"), "{err}");
    }

    #[test]
    fn an_image_without_panic_call_sites_passes() {
        let asm = "  200:  bl  0x300 <step>\n  402:  bl  0x300 <step>\n  104:  b.w 0x300 <step>\n";
        let reach = check_disassembly(&image(), asm).unwrap();
        assert_eq!(reach.functions, 6, "five roots and step");
    }

    #[test]
    fn an_indirect_call_after_init_is_refused_and_a_missing_root_too() {
        let err = check_disassembly(&image(), "  200:  bl  0x300 <step>\n  302:  blx r3\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("indirect"), "{err}");
        let err = check_disassembly(&image()[1..], "").unwrap_err().to_string();
        assert!(err.contains("EXTI0"), "{err}");
    }

    #[test]
    fn branch_mnemonics() {
        for m in ["b", "bl", "b.w", "beq", "bne.w", "cbz", "cbnz", "bhs.n"] {
            assert!(is_direct_branch(m), "{m}");
        }
        for m in ["bic", "bics", "bfi", "bkpt", "blx", "bx", "ble.x"] {
            assert!(!is_direct_branch(m), "{m}");
        }
    }
}

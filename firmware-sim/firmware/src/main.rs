//! The radiosity device as Cortex-M firmware: the table in flash (flat or hierarchical: the build script names
//! its type, `FirmwareTable`), the solver in static buffers sized from the table's counts, every compiled-in
//! relight script run through firmware-sim's device loop (the same for both formats), each frame timed
//! with SysTick under QEMU's `-icount` (deterministic: instructions, not wall time); a table with a transfer
//! basis is then relit from it at every script's states (`run_transfer`, timed the same way). Output goes through
//! semihosting, one line per event (format: `firmware_sim::qemu` module docs); the exit status is 0 if every
//! script ran.
//!
//! Stack high-water mark: cortex-m-rt's `paint-stack` feature fills the stack region (`_stack_end` up to
//! `_stack_start`, everything in RAM above the statics) with `STACK_PAINT_VALUE` in the reset handler, before
//! `main`. After the last script [`stack_use`] scans up from the bottom of the region for the first word that
//! is no longer paint: everything above it has been used, by the deepest call chain or an exception frame.
//! A word that happened to be written with the paint value at the very bottom would be missed, so the mark is
//! exact up to such a coincidence, never an overestimate.
//!
//! Faults: a HardFault (every fault on the Cortex-M0; on the Cortex-M4 the configurable faults escalate to it,
//! since none is enabled) prints the stacked registers as an `E,hardfault,...` line and exits through
//! semihosting with a failure status, so a QEMU run ends with an error instead of hanging. The feature
//! `fault-test` executes an undefined instruction after boot to exercise that path.
//!
//! `unsafe`, and why: the buffers need none (they are `static mut` locals of the `#[entry]` function, which
//! cortex-m-rt hands out as `&'static mut` exactly once). Two places need it: cortex-m-rt requires the
//! HardFault handler to be declared `unsafe fn`, and [`stack_use`] reads the painted words, memory no Rust
//! object owns, with `read_volatile` (one `unsafe` block; its bounds are the linker's symbols).
#![no_std]
#![no_main]

use core::fmt::{self, Write};
use core::panic::PanicInfo;
use core::sync::atomic::{compiler_fence, AtomicU32, Ordering};

use cortex_m::peripheral::{syst::SystClkSource, SYST};
use cortex_m_rt::{entry, exception, ExceptionFrame, STACK_PAINT_VALUE};
use cortex_m_semihosting::{debug, hio};
use firmware_sim::device::{
    run_script, run_transfer, write_trace, write_transfer_trace, Bits, Meter, TransferRecord, TRANSFER_CHUNK,
};
use radiosity_core::{Scalar, TransferTable};
mod generated {
    include!(concat!(env!("OUT_DIR"), "/generated.rs"));
}
use generated::{DeviceBuffers, FirmwareTable, INSTRUCTIONS_PER_TICK, LIGHT_GROUPS, SCRIPTS, TABLE};

/// The solver's arithmetic.
#[cfg(not(feature = "fixed"))]
type S = f32;
/// The solver's arithmetic.
#[cfg(feature = "fixed")]
type S = radiosity_core::Fixed;

/// SysTick reload: the full 24 bits, so the counter wraps every 2^24 ticks.
const RELOAD: u32 = 0x00FF_FFFF;
/// Iterations of the calibration loop (`cortex_m::asm::delay`: `subs` + `bne`, 2 instructions each).
const CAL_CYCLES: u32 = 2_000_000;

/// SysTick wraps counted by the exception handler (only the handler writes it: load/store, no CAS, so it
/// works on the Cortex-M0 as well).
static WRAPS: AtomicU32 = AtomicU32::new(0);

#[exception]
fn SysTick() {
    WRAPS.store(WRAPS.load(Ordering::Relaxed).wrapping_add(1), Ordering::Relaxed);
}

/// Ticks since SysTick started: wraps times 2^24 plus the down-counter's progress. Re-reads if a wrap was
/// counted in between.
fn now_ticks() -> u64 {
    loop {
        let w1 = WRAPS.load(Ordering::Relaxed);
        let current = SYST::get_current();
        let w2 = WRAPS.load(Ordering::Relaxed);
        if w1 == w2 {
            return (u64::from(w1) << 24) + u64::from(RELOAD - current);
        }
    }
}

/// Instructions per frame from SysTick (resolution one tick: 40 instructions on mps2-an386, 62.5 on microbit).
struct SysTickMeter {
    start: u64,
}

impl Meter for SysTickMeter {
    fn start(&mut self) {
        self.start = now_ticks();
        // Keep the measured work after the read (the compiler may otherwise move memory accesses across it).
        compiler_fence(Ordering::SeqCst);
    }
    fn stop(&mut self) -> u64 {
        compiler_fence(Ordering::SeqCst);
        // Instructions per tick (from the build script): SysTick runs on the board clock (mps2-an386 25 MHz,
        // microbit 16 MHz) and `-icount shift=0` makes one instruction take 1 ns of virtual time. Checked at
        // boot by `CAL`.
        let (num, den) = INSTRUCTIONS_PER_TICK;
        now_ticks().saturating_sub(self.start) * num / den
    }
}

/// One output line, assembled in RAM and written with one semihosting call.
struct Line {
    buf: [u8; 256],
    len: usize,
}

impl Write for Line {
    fn write_str(&mut self, s: &str) -> fmt::Result {
        let end = self.len + s.len();
        let dst = self.buf.get_mut(self.len..end).ok_or(fmt::Error)?;
        dst.copy_from_slice(s.as_bytes());
        self.len = end;
        Ok(())
    }
}

fn emit(args: fmt::Arguments<'_>) {
    let mut line = Line { buf: [0; 256], len: 0 };
    let _ = line.write_fmt(args);
    let _ = line.write_str("\n");
    if let Ok(mut out) = hio::hstdout() {
        let _ = out.write_all(&line.buf[..line.len]);
    }
}

/// A frame's trace line, for `emit`.
struct Trace<'a>(&'a str, &'a firmware_sim::device::FrameRecord<S>);

impl fmt::Display for Trace<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write_trace(f, self.0, self.1)
    }
}

/// A transfer relight's trace line, for `emit`.
struct TransferTrace<'a>(&'a str, &'a TransferRecord);

impl fmt::Display for TransferTrace<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write_transfer_trace::<S, _>(f, self.0, self.1)
    }
}

#[entry]
fn main() -> ! {
    static mut BUFFERS: DeviceBuffers<S> = DeviceBuffers::<S>::new();
    // The transfer pass's output, one chunk of elements at a time, and its intensities.
    static mut CHUNK: [[S; 3]; TRANSFER_CHUNK] = [[<S as Scalar>::ZERO; 3]; TRANSFER_CHUNK];
    static mut INTENSITY: [[S; 3]; LIGHT_GROUPS] = [[<S as Scalar>::ZERO; 3]; LIGHT_GROUPS];

    let Some(mut p) = cortex_m::Peripherals::take() else { fail("peripherals taken twice") };
    p.SYST.set_clock_source(SystClkSource::Core);
    p.SYST.set_reload(RELOAD);
    p.SYST.clear_current();
    p.SYST.enable_interrupt();
    p.SYST.enable_counter();
    // The counter reads 0 until its first reload; start measuring after that.
    while SYST::get_current() == 0 {}

    // Calibration: a loop of known length (2 instructions per iteration, `CAL_CYCLES + 1` iterations), minus
    // the cost of an empty measurement.
    let mut meter = SysTickMeter { start: 0 };
    // `delay` is `nomem` inline assembly, which the compiler may move across the SysTick reads; `dsb` (a
    // memory clobber) pins it between them. Both measurements contain the two `dsb`s.
    meter.start();
    cortex_m::asm::dsb();
    cortex_m::asm::dsb();
    let empty = meter.stop();
    meter.start();
    cortex_m::asm::dsb();
    cortex_m::asm::delay(CAL_CYCLES);
    cortex_m::asm::dsb();
    let measured = meter.stop().saturating_sub(empty);
    emit(format_args!("CAL,{},{}", 2 * (u64::from(CAL_CYCLES) + 1), measured));

    if cfg!(feature = "fault-test") {
        cortex_m::asm::udf();
    }

    let table = match FirmwareTable::parse(TABLE) {
        Ok(t) => t,
        Err(e) => {
            emit(format_args!("E,table,{e}"));
            fail("bad table");
        }
    };
    let mut failures = 0u32;
    for script in SCRIPTS {
        let result = run_script(&table, BUFFERS.buffers(), script, &mut meter, |record, _| {
            emit(format_args!("{}", Trace(script.name, record)));
        });
        match result {
            Ok(units) => emit(format_args!("B,{},{},{units}", <S as Bits>::NAME, script.name)),
            Err(e) => {
                failures += 1;
                emit(format_args!("E,{},{e}", script.name));
            }
        }
    }
    // A table with a transfer basis: every script's states relit from it, in chunks.
    if table.transfer_section().is_some() {
        for script in SCRIPTS {
            let result = run_transfer(&table, script, (&mut *CHUNK, &mut *INTENSITY), &mut meter, |record| {
                emit(format_args!("{}", TransferTrace(script.name, record)));
            });
            if let Err(e) = result {
                failures += 1;
                emit(format_args!("E,{},transfer: {e}", script.name));
            }
        }
    }
    let stack = stack_use();
    emit(format_args!("STACK,{},{}", stack.high_water, stack.size));
    emit(format_args!("DONE,{failures}"));
    debug::exit(if failures == 0 { debug::EXIT_SUCCESS } else { debug::EXIT_FAILURE });
    loop {
        cortex_m::asm::wfi();
    }
}

extern "C" {
    /// The bottom of the stack region (cortex-m-rt's `link.x`: the end of `.bss` and `.uninit`, aligned).
    static _stack_end: u32;
    /// The top of the stack region: the initial stack pointer (the end of RAM).
    static _stack_start: u32;
}

/// The stack's use as the paint shows it, in bytes.
struct StackUse {
    /// From the top of the region down to the deepest word that is no longer paint.
    high_water: usize,
    /// The whole region, `_stack_start - _stack_end`.
    size: usize,
}

/// Scans the painted stack region from the bottom up for the first word that is no longer
/// `STACK_PAINT_VALUE` (see the crate docs).
fn stack_use() -> StackUse {
    // Taking the address of an extern static is safe; only reading through it is not.
    let bottom = core::ptr::addr_of!(_stack_end) as usize;
    let top = core::ptr::addr_of!(_stack_start) as usize;
    let mut addr = bottom;
    while addr < top {
        // SAFETY: `bottom..top` is RAM (the linker placed it inside the memory map's RAM region and asserts
        // `_stack_end <= _stack_start`), both ends are 4-byte aligned (asserted by `link.x` for `_stack_end`,
        // 8 for `_stack_start`), so every aligned word in between is a valid `u32` to read. Part of it is the
        // live stack, which this only reads; volatile keeps the compiler from assuming anything about it.
        let word = unsafe { core::ptr::read_volatile(core::ptr::with_exposed_provenance::<u32>(addr)) };
        if word != STACK_PAINT_VALUE {
            break;
        }
        addr += 4;
    }
    StackUse { high_water: top - addr, size: top - bottom }
}

/// Reports the fault (the registers the CPU stacked on entry: the faulting instruction is `pc`) and exits
/// with a failure status. `unsafe` only because cortex-m-rt requires that of a HardFault handler.
#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    emit(format_args!(
        "E,hardfault,pc={:#010x} lr={:#010x} xpsr={:#010x} r0={:#010x} r1={:#010x} r2={:#010x} r3={:#010x} \
         r12={:#010x}",
        ef.pc(),
        ef.lr(),
        ef.xpsr(),
        ef.r0(),
        ef.r1(),
        ef.r2(),
        ef.r3(),
        ef.r12()
    ));
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

fn fail(why: &str) -> ! {
    emit(format_args!("E,firmware,{why}"));
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

#[panic_handler]
fn panic(info: &PanicInfo) -> ! {
    emit(format_args!("E,panic,{info}"));
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

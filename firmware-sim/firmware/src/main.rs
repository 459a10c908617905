//! The radiosity device as Cortex-M firmware: the table in flash, the solver in static buffers sized from the
//! table's counts, every compiled-in relight script run through firmware-sim's device loop, each frame timed
//! with SysTick under QEMU's `-icount` (deterministic: instructions, not wall time). Output goes through
//! semihosting, one line per event (format: `firmware_sim::qemu` module docs); the exit status is 0 if every
//! script ran.
//!
//! No `unsafe` here: the buffers are `static mut` locals of the `#[entry]` function, which cortex-m-rt hands
//! out as `&'static mut` exactly once.
#![no_std]
#![no_main]

use core::fmt::{self, Write};
use core::panic::PanicInfo;
use core::sync::atomic::{compiler_fence, AtomicU32, Ordering};

use cortex_m::peripheral::{syst::SystClkSource, SYST};
use cortex_m_rt::{entry, exception};
use cortex_m_semihosting::{debug, hio};
use firmware_sim::device::{run_script, write_trace, Bits, Meter};
use radiosity_core::Table;

mod generated {
    include!(concat!(env!("OUT_DIR"), "/generated.rs"));
}
use generated::{DeviceBuffers, INSTRUCTIONS_PER_TICK, SCRIPTS, TABLE};

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

#[entry]
fn main() -> ! {
    static mut BUFFERS: DeviceBuffers<S> = DeviceBuffers::<S>::new();

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

    let table = match Table::parse(TABLE) {
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
    emit(format_args!("DONE,{failures}"));
    debug::exit(if failures == 0 { debug::EXIT_SUCCESS } else { debug::EXIT_FAILURE });
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

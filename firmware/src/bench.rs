//! Instruction counting for `cargo xtask bench`: SysTick free-running on the core clock.
//! Under `qemu-system-arm -icount shift=0` one guest instruction is one nanosecond of
//! virtual time, so SysTick counts instructions (in ticks of a fixed ratio); the ratio is
//! calibrated at boot against a loop of exactly known length, not assumed.

use core::hint::black_box;

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use estimator_core::sensor::{AdcError, AdcSource};

use crate::pipeline::{self, Pipeline, SampleMessage, SampleQueue, QUEUE_CAPACITY};

const RELOAD: u32 = 0x00ff_ffff;

/// Start SysTick free-running, without its interrupt.
pub fn start(syst: &mut SYST) {
    syst.set_clock_source(SystClkSource::Core);
    syst.set_reload(RELOAD);
    syst.clear_current();
    syst.enable_counter();
}

/// The counter now (it counts down).
#[inline(always)]
pub fn now() -> u32 {
    SYST::get_current()
}

/// Ticks from `start` to now, for intervals shorter than one wrap (2^24 ticks).
#[inline(always)]
pub fn since(start: u32) -> u32 {
    start.wrapping_sub(now()) & RELOAD
}

/// Accumulated ticks over a number of events.
#[derive(Clone, Copy, Debug, Default)]
pub struct Totals {
    /// Sum of ticks.
    pub ticks: u64,
    /// Events summed.
    pub events: u32,
}

impl Totals {
    /// Add one event of `ticks`.
    #[inline(always)]
    pub fn add(&mut self, ticks: u32) {
        self.ticks += ticks as u64;
        self.events += 1;
    }
}

/// Execute exactly `2 · iterations` instructions (`subs` + `bne` per iteration).
#[inline(never)]
pub fn known_loop(iterations: u32) {
    if iterations == 0 {
        return;
    }
    // Safety: a register-only countdown loop; it touches no memory.
    unsafe {
        core::arch::asm!(
            "1:",
            "subs {0}, {0}, #1",
            "bne 1b",
            inout(reg) iterations => _,
            options(nomem, nostack),
        );
    }
}

/// Ticks of two loops of known length: their difference is `2 · iterations` instructions.
pub fn calibrate(iterations: u32) -> (u32, u32) {
    let start = now();
    known_loop(iterations);
    let short = since(start);
    let start = now();
    known_loop(2 * iterations);
    let long = since(start);
    (short, long)
}

/// A converter seen as its data register: one volatile load per read, like the real ADC.
pub struct RegisterAdc {
    data_register: u32,
}

impl RegisterAdc {
    /// A register holding `code`.
    pub fn new(code: u32) -> Self {
        Self {
            data_register: code,
        }
    }
}

impl AdcSource for RegisterAdc {
    fn max_code(&self) -> u32 {
        65_535
    }

    #[inline(always)]
    fn read(&mut self) -> Result<u32, AdcError> {
        // Safety: reads a field of `self` through a valid, aligned reference; volatile only
        // so the compiler cannot hoist the load out of the measured loop.
        Ok(unsafe { core::ptr::read_volatile(&self.data_register) })
    }
}

/// Ticks for `rounds × (QUEUE_CAPACITY − 1)` hand-offs, each followed by `after_each` (the
/// interrupt acknowledge and the pend of the estimator task, as in the ISR); the queue is
/// drained between rounds, outside the measurement. Returns (ticks, hand-offs).
pub fn measure_handoff(rounds: u32, mut after_each: impl FnMut()) -> (u64, u32) {
    let mut queue = SampleQueue::new();
    let (mut producer, mut consumer) = queue.split();
    let mut adc = RegisterAdc::new(30_000);
    let mut sequence = 0u32;
    let per_round = QUEUE_CAPACITY as u32 - 1;
    let mut ticks = 0u64;
    for _ in 0..rounds {
        let start = now();
        for _ in 0..per_round {
            pipeline::hand_off(&mut adc, &mut producer, &mut sequence);
            after_each();
        }
        ticks += since(start) as u64;
        for _ in 0..QUEUE_CAPACITY {
            if black_box(consumer.dequeue()).is_none() {
                break;
            }
        }
    }
    (ticks, rounds * per_round)
}

/// Ticks for feeding `messages` through the estimator task's work (`Pipeline::accept`:
/// sequence check, scale, estimator), one measurement over the whole slice. The lines it
/// returns are kept where `accept` wrote them, as the task keeps them (`pipeline::estimate`
/// looks at them in place): passed to `black_box` by value they were copied, 132 B per
/// sample, about 135 instructions of the figure that the firmware never runs.
pub fn measure_pipeline(pipeline: &mut Pipeline, messages: &[SampleMessage]) -> u64 {
    let start = now();
    for message in messages {
        let lines = pipeline.accept(*message);
        black_box(&lines);
    }
    since(start) as u64
}

/// Ticks of the same loop without the work, to subtract.
pub fn measure_loop_overhead(messages: &[SampleMessage]) -> u64 {
    let start = now();
    for message in messages {
        black_box(*message);
    }
    since(start) as u64
}

/// What the free stack is filled with, to find how deep it was used later.
const STACK_PAINT: u32 = 0xA5A5_5A5A;

/// The usable stack's bounds, as addresses: (lowest, highest): above the guard
/// (`fault::guard_stack`), which may not be touched.
fn stack_bounds() -> (usize, usize) {
    let (_, guard_end) = crate::fault::guard_range();
    let (_, highest) = crate::fault::stack_bounds();
    (guard_end as usize, highest as usize)
}

/// Fill the free stack, from the guard up to `margin` bytes below the stack pointer, with
/// [`STACK_PAINT`]; the stack pointer it painted below. Inlined, so the stack pointer is
/// its caller's.
#[inline(always)]
fn paint_below_sp(margin: usize) -> usize {
    let (lowest, _) = stack_bounds();
    let sp = cortex_m::register::msp::read() as usize;
    let mut address = lowest;
    while address < sp - margin {
        // Safety: the words between the guard and `margin` bytes below the stack pointer
        // belong to no live frame (the stack grows down and nothing else is placed there:
        // flip-link puts `.data`/`.bss` above it), and interrupts are off in `init`.
        unsafe { core::ptr::write_volatile(address as *mut u32, STACK_PAINT) };
        address += 4;
    }
    sp
}

/// The lowest address below `limit` (from the guard up) no longer painted: the deepest
/// the stack went since it was painted; `limit` if nothing was.
fn deepest_written(limit: usize) -> usize {
    let (lowest, _) = stack_bounds();
    let mut address = lowest;
    // Safety: reads words of the stack region between the guard and `limit`.
    while address < limit
        && unsafe { core::ptr::read_volatile(address as *const u32) } == STACK_PAINT
    {
        address += 4;
    }
    address
}

/// Fill the stack below the current stack pointer (less a margin for this function) with
/// [`STACK_PAINT`]. Call it early in `init`, with interrupts still disabled.
#[inline(never)]
pub fn paint_stack() {
    paint_below_sp(256);
}

/// Bytes of the stack used since [`paint_stack`] (the deepest word no longer painted), and
/// the stack's size.
pub fn stack_used() -> (u32, u32) {
    let (lowest, highest) = stack_bounds();
    (
        (highest - deepest_written(highest)) as u32,
        (highest - lowest) as u32,
    )
}

/// Bytes of stack `work` used below the caller's stack pointer: the free stack (down to
/// the guard) is painted, `work` runs, and the deepest word it wrote is found.
#[inline(never)]
pub fn stack_depth_of(work: impl FnOnce()) -> u32 {
    let sp = paint_below_sp(16);
    work();
    (sp - deepest_written(sp)) as u32
}

/// A shared resource as RTIC's `lock` sees it, for running a task's body from `init`.
pub struct Unshared<'a, T>(pub &'a mut T);

/// A serial port that takes every byte and sends none: the console's formatting measured
/// without a UART.
pub struct Discard;

impl crate::console::SerialPort for Discard {
    fn write_bytes(&mut self, bytes: &[u8]) -> usize {
        core::hint::black_box(bytes).len()
    }
}

impl<T> rtic::Mutex for Unshared<'_, T> {
    type T = T;

    fn lock<R>(&mut self, work: impl FnOnce(&mut T) -> R) -> R {
        work(self.0)
    }
}

/// The hand-off's stack: one [`pipeline::hand_off`] from a register converter into a
/// queue, as the sample ISR runs it.
pub fn handoff_stack() -> u32 {
    let mut queue = SampleQueue::new();
    let (mut producer, _consumer) = queue.split();
    let mut adc = RegisterAdc::new(30_000);
    let mut sequence = 0u32;
    stack_depth_of(|| pipeline::hand_off(&mut adc, &mut producer, &mut sequence))
}

/// The estimator task's stack: its body ([`pipeline::estimate`]) on each chunk of
/// `messages` in turn, queued as the hand-off queues them; the deepest of all chunks.
/// `readout_task` is pended as the task pends its readout: the caller unpends it.
pub fn estimator_stack<I: cortex_m::interrupt::InterruptNumber + Copy>(
    pipeline: &mut Pipeline,
    latest: &mut pipeline::Lines,
    messages: &[SampleMessage],
    readout_task: I,
) -> u32 {
    let mut queue = SampleQueue::new();
    let (mut producer, mut consumer) = queue.split();
    let mut deepest = 0;
    for chunk in messages.chunks(QUEUE_CAPACITY - 1) {
        for message in chunk {
            let _ = producer.enqueue(*message);
        }
        let depth = stack_depth_of(|| {
            pipeline::estimate(
                &mut Unshared(&mut *pipeline),
                &mut Unshared(&mut *latest),
                &mut consumer,
                readout_task,
            )
        });
        deepest = deepest.max(depth);
    }
    deepest
}

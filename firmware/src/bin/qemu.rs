//! The weighing firmware on QEMU `mps2-an386`: a 4 kHz CMSDK timer interrupt takes samples
//! from the simulated load cell, the estimator task runs the weighing core, and a readout
//! task logs 20 lines a second over semihosting (defmt). After the 4 s demo scene it exits
//! QEMU with status 0; a panic or fault exits with status 1.
#![no_std]
#![no_main]

use defmt_semihosting as _;

#[rtic::app(device = firmware::mps2_an386, peripherals = false)]
mod app {
    use estimator_core::Scale;
    use firmware::mps2_an386::{CmsdkTimer, Interrupt, SYSTEM_CLOCK_HZ};
    use firmware::pipeline::{
        self, Pipeline, Readout, SampleMessage, SampleQueue, QUEUE_CAPACITY, SAMPLE_RATE_HZ,
    };
    use firmware::qemu::{self, load_cell, RamCalibrationStore, SimulatedConverter};
    use heapless::spsc::{Consumer, Producer};

    #[cfg(feature = "bench")]
    use firmware::bench;

    type LoadCell = load_cell::LoadCell;

    /// The load cell of the demo scene.
    fn new_load_cell() -> LoadCell {
        load_cell::demo_scene()
    }

    /// The demo scene lasts 4.0 s.
    const SCENE_SAMPLES: u32 = 4 * SAMPLE_RATE_HZ;

    #[shared]
    struct Shared {
        latest: Option<Readout>,
    }

    #[local]
    struct Local {
        timer: CmsdkTimer,
        converter: SimulatedConverter<LoadCell>,
        producer: Producer<'static, SampleMessage>,
        consumer: Consumer<'static, SampleMessage>,
        pipeline: Pipeline,
        sequence: u32,
    }

    #[init(local = [queue: SampleQueue = SampleQueue::new()])]
    fn init(cx: init::Context) -> (Shared, Local) {
        // The factory calibration (known mass, empty pan) on the simulated chain, stored as
        // a record and read back through the same CRC-checked decoder as flash on hardware.
        defmt::println!("factory calibration: 6 s of the simulated cell, empty then 200 g...");
        let defaults = load_cell::nominal_calibration();
        let record = match load_cell::factory_calibration() {
            Ok(factory) => factory.encode(),
            Err(error) => {
                defmt::error!("factory calibration failed: {}", error);
                [0xFF; estimator_core::calibration::RECORD_LEN]
            }
        };
        let store = RamCalibrationStore::with_record(record);
        let (calibration, source) = store.load(defaults);
        defmt::println!(
            "calibration counts_per_gram={=f32} zero_counts={=f32} source={}",
            calibration.counts_per_gram,
            calibration.zero_counts,
            source
        );

        let config = pipeline::scale_config();
        let scale = match Scale::new(config, calibration.counts_scale()) {
            Ok(scale) => scale,
            Err(error) => {
                defmt::error!("scale configuration refused: {}", error);
                qemu::exit(false)
            }
        };
        defmt::println!(
            "config order={=usize} decimation={=u16} sample_rate_hz={=u32}",
            config.order,
            config.decimation,
            SAMPLE_RATE_HZ
        );

        #[cfg(feature = "bench")]
        run_benchmarks(cx.core.SYST, Pipeline::new(scale.clone()));
        #[cfg(not(feature = "bench"))]
        let _ = cx.core;

        let (producer, consumer) = cx.local.queue.split();
        let converter = SimulatedConverter::new(new_load_cell());
        // Safety: the only CmsdkTimer for timer 0; it moves into the hand-off task.
        let mut timer = unsafe { CmsdkTimer::timer0() };
        timer.start_periodic(SYSTEM_CLOCK_HZ / SAMPLE_RATE_HZ);

        (
            Shared { latest: None },
            Local {
                timer,
                converter,
                producer,
                consumer,
                pipeline: Pipeline::new(scale),
                sequence: 0,
            },
        )
    }

    /// The sample hand-off: no math, no logging. A full queue leaves a gap in the sequence
    /// numbers, which the estimator task counts as dropped samples.
    #[task(binds = Timer0, priority = 3, local = [timer, converter, producer, sequence])]
    fn sample_handoff(cx: sample_handoff::Context) {
        cx.local.timer.clear_interrupt();
        pipeline::hand_off(cx.local.converter, cx.local.producer, cx.local.sequence);
        rtic::pend(Interrupt::Uart0Rx);
        // The simulated analogue hardware produces the next conversion (not the hand-off).
        cx.local.converter.convert();
    }

    /// The estimator task: drains the queue (bounded by its capacity) into the weighing core.
    #[task(binds = Uart0Rx, priority = 2, local = [consumer, pipeline], shared = [latest])]
    fn estimate(mut cx: estimate::Context) {
        for _ in 0..QUEUE_CAPACITY {
            let Some(message) = cx.local.consumer.dequeue() else {
                break;
            };
            if let Some(readout) = cx.local.pipeline.accept(message) {
                cx.shared.latest.lock(|latest| *latest = Some(readout));
                rtic::pend(Interrupt::Uart1Rx);
            }
        }
    }

    /// The readout task: 20 lines a second, then the end-of-scene summary and exit.
    #[task(binds = Uart1Rx, priority = 1, shared = [latest])]
    fn readout(mut cx: readout::Context) {
        let Some(readout) = cx.shared.latest.lock(|latest| latest.take()) else {
            return;
        };
        pipeline::log_readout(&readout);
        if readout.sample >= SCENE_SAMPLES {
            defmt::println!(
                "end samples={=u32} dropped={=u32}",
                readout.sample,
                readout.dropped
            );
            qemu::exit(true)
        }
    }

    /// Instruction counts (feature `bench`, run under `-icount shift=0`): the hand-off and
    /// the estimator task's work, replayed on the same functions the tasks call, so each
    /// figure is one long measurement instead of many one-tick ones.
    #[cfg(feature = "bench")]
    fn run_benchmarks(mut syst: cortex_m::peripheral::SYST, mut pipeline: Pipeline) {
        use estimator_core::{AdcSource, RawSample};
        use firmware::pipeline::SampleMessage;

        bench::start(&mut syst);
        let iterations = 100_000;
        let (short, long) = bench::calibrate(iterations);
        defmt::println!(
            "bench calibration instructions={=u32} short={=u32} long={=u32}",
            2 * iterations,
            short,
            long
        );

        // Safety: timer 1 is not used by the application; this is its only handle.
        let mut spare_timer = unsafe { CmsdkTimer::timer1() };
        let (ticks, events) = bench::measure_handoff(100, || {
            spare_timer.clear_interrupt();
            rtic::pend(Interrupt::Uart2Rx);
        });
        // Uart2Rx is never enabled, so the pend only costs what the real one costs.
        cortex_m::peripheral::NVIC::unpend(Interrupt::Uart2Rx);
        defmt::println!("bench handoff ticks={=u64} events={=u32}", ticks, events);

        let mut converter = SimulatedConverter::new(new_load_cell());
        let mut chunk = [SampleMessage {
            sequence: 0,
            sample: RawSample::Lost,
        }; 2000];
        let mut sequence = 0u32;
        let mut ticks = 0u64;
        let mut model_ticks = 0u64;
        for _ in 0..SCENE_SAMPLES as usize / chunk.len() {
            let model_start = bench::now();
            for message in chunk.iter_mut() {
                let sample = match converter.read() {
                    Ok(code) if converter.is_saturated(code) => RawSample::Saturated,
                    Ok(code) => RawSample::Counts(code as i32),
                    Err(_) => RawSample::Lost,
                };
                converter.convert();
                *message = SampleMessage { sequence, sample };
                sequence += 1;
            }
            model_ticks += bench::since(model_start) as u64;
            let work = bench::measure_pipeline(&mut pipeline, &chunk);
            let overhead = bench::measure_loop_overhead(&chunk);
            ticks += work.saturating_sub(overhead);
        }
        defmt::println!(
            "bench model ticks={=u64} events={=u32}",
            model_ticks,
            sequence
        );
        defmt::println!(
            "bench estimator ticks={=u64} events={=u32} dropped={=u32}",
            ticks,
            sequence,
            pipeline.dropped()
        );
    }
}

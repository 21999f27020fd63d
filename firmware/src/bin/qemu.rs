//! The weighing firmware on QEMU `mps2-an386`: a 4 kHz CMSDK timer interrupt takes samples
//! from the simulated load cell, the estimator task runs the weighing core, a readout task
//! logs 20 lines a second over semihosting (defmt), and UART 0 is the serial console
//! (`firmware::console`): the command task takes the operator's lines (`tare`, `cal 200`,
//! `unit kg`, `rate 50`, `config set …`, `help`), and reading lines go out at the console's
//! rate, each outcome as its own line. After
//! the scene (the demo, or the command scene when QEMU's semihosting command line names it)
//! it exits QEMU with status 0; a panic or fault exits with status 1, and so does the
//! watchdog's NMI when no new sample has reached the readout task for a second (the scenes
//! `stall` and `stack-overflow` break the board on purpose to show both).
#![no_std]
#![no_main]

use defmt_semihosting as _;

#[rtic::app(device = firmware::mps2_an386, peripherals = false)]
mod app {
    use estimator_core::weighing::CalibrationStore;
    use firmware::console::Console;
    use firmware::fault;
    use firmware::mps2_an386::{CmsdkTimer, CmsdkUart, CmsdkWatchdog, Interrupt, SYSTEM_CLOCK_HZ};
    use firmware::pipeline::{
        self, EstimatorStorage, FirmwareRecorder, Lines, Pipeline, SampleMessage, SampleQueue,
        SampleWatchdog, SAMPLE_RATE_HZ,
    };
    use firmware::qemu::{self, QemuCalibrationStore, Scene, SimulatedConverter};
    use heapless::spsc::{Consumer, Producer};
    use host_sim::qemu_scenes;

    #[cfg(feature = "bench")]
    use estimator_core::weighing::RawSample;
    #[cfg(feature = "bench")]
    use firmware::bench;

    type LoadCell = qemu_scenes::LoadCell;

    /// The console's baud rate (QEMU ignores it; real CMSDK silicon would not).
    const CONSOLE_BAUD: u32 = 115_200;
    /// `D` lines of a recording written per readout tick: 3.4 KB, faster than the 115,200
    /// baud the UART is set to (QEMU does not pace it), so a 1.25 s recording is out in
    /// 0.5 s; faster, the console socket fills while the harness's reader waits for a core.
    const RECORD_LINES_PER_TICK: usize = 32;
    /// Bytes taken per receive interrupt: the UART holds one, and one more may land while
    /// the first is decided.
    const BYTES_PER_INTERRUPT: usize = 4;
    /// The readout task's vector, pended by the estimator task after each readout.
    const READOUT: Interrupt = Interrupt::Uart1Rx;

    #[shared]
    struct Shared {
        latest: Lines,
        pipeline: Pipeline,
        console: Console<CmsdkUart>,
        store: QemuCalibrationStore,
    }

    #[local]
    struct Local {
        timer: CmsdkTimer,
        converter: SimulatedConverter<LoadCell>,
        producer: Producer<'static, SampleMessage>,
        consumer: Consumer<'static, SampleMessage>,
        sequence: u32,
        scene_samples: u32,
        scene: Scene,
        stall_at: Option<u32>,
        watchdog: SampleWatchdog<CmsdkWatchdog>,
    }

    #[init(local = [
        queue: SampleQueue = SampleQueue::new(),
        estimator: EstimatorStorage = EstimatorStorage::UNCONFIGURED,
        recorder: FirmwareRecorder = FirmwareRecorder::new(),
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        // The stack `idle` will run on: what `main` and this function's entry took.
        #[cfg(feature = "bench")]
        let init_sp = cortex_m::register::msp::read();
        let mut core = cx.core;
        fault::guard_stack(&mut core.MPU, &mut core.SCB);
        // The factory calibration (known mass, empty pan) on the simulated chain, stored as
        // a record in the flash store and read back through the same CRC-checked decoder and
        // limits as flash on hardware; a flash image from an earlier run (a reset) keeps its
        // own record instead.
        #[cfg(feature = "bench")]
        bench::paint_stack();
        let limits = qemu_scenes::calibration_limits();
        let mut store = qemu::calibration_store();
        if matches!(store.read_record(), Ok(Some(_))) {
            defmt::println!("factory calibration: the flash image holds a record already");
        } else {
            defmt::println!("factory calibration: 6 s of the simulated cell, empty then 200 g...");
            match qemu_scenes::factory_calibration() {
                Ok(factory) => {
                    if let Err(error) = store.write_record(&factory.encode()) {
                        defmt::error!("factory calibration not stored: {}", error);
                    }
                }
                Err(error) => defmt::error!("factory calibration failed: {}", error),
            }
        }
        let (calibration, source) = qemu::load_calibration(&mut store, &limits);
        pipeline::log_calibration(&calibration, &source);

        let scale = match pipeline::scale(calibration.counts_scale(), cx.local.estimator) {
            Ok(scale) => scale,
            Err(error) => {
                defmt::error!("weighing configuration refused: {}", error);
                qemu::exit(false)
            }
        };
        pipeline::log_config();
        let mut pipeline = Pipeline::new(scale, limits, source, cx.local.recorder);
        let unit = pipeline::load_settings(&mut store, &mut pipeline);

        // The benchmarks replay a scene through the application's own pipeline and then
        // restart it: a second one would need a second estimator (20 KB for a model bank).
        #[cfg(feature = "bench")]
        let pipeline = {
            let mut pipeline = pipeline;
            run_benchmarks(core.SYST, &mut pipeline, &mut store, &calibration, init_sp);
            pipeline
        };

        let scene = match Scene::from_command_line() {
            Ok(scene) => scene,
            Err(error) => {
                defmt::error!("{} on the semihosting command line", error);
                qemu::exit(false)
            }
        };
        let load_cell = scene.load_cell();
        let scene_samples = scene.samples(&load_cell);
        defmt::println!(
            "scene {} samples={=u32} console on UART 0 (type help)",
            scene,
            scene_samples
        );

        let (producer, consumer) = cx.local.queue.split();
        let converter = SimulatedConverter::new(load_cell);
        // Safety: the only CmsdkUart for UART 0; it moves into the command task.
        let mut uart = unsafe { CmsdkUart::uart0() };
        uart.start(CONSOLE_BAUD);
        let mut console = Console::new(uart);
        console.set_unit(unit);
        console.banner();
        // Safety: the only CmsdkTimer for timer 0; it moves into the hand-off task.
        let mut timer = unsafe { CmsdkTimer::timer0() };
        timer.start_periodic(SYSTEM_CLOCK_HZ / SAMPLE_RATE_HZ);
        // Safety: the only CmsdkWatchdog; it moves into the readout task, which feeds it.
        let mut watchdog = unsafe { CmsdkWatchdog::take() };
        watchdog.start(SYSTEM_CLOCK_HZ / 1000 * qemu::WATCHDOG_TIMEOUT_MS);

        (
            Shared {
                latest: Lines::default(),
                pipeline,
                console,
                store,
            },
            Local {
                timer,
                converter,
                producer,
                consumer,
                sequence: 0,
                scene_samples,
                scene,
                stall_at: scene.stalls_after(),
                watchdog: SampleWatchdog::new(watchdog, 0),
            },
        )
    }

    /// The sample hand-off: no math, no logging. A full queue leaves a gap in the sequence
    /// numbers, which the estimator task counts as dropped samples. (The `stall` scene
    /// stops the timer here: the board's sample clock failing.)
    #[task(binds = Timer0, priority = 3, local = [timer, converter, producer, sequence, stall_at])]
    fn sample_handoff(cx: sample_handoff::Context) {
        cx.local.timer.clear_interrupt();
        if Some(*cx.local.sequence) == *cx.local.stall_at {
            cx.local.timer.stop();
            return;
        }
        pipeline::hand_off(cx.local.converter, cx.local.producer, cx.local.sequence);
        rtic::pend(Interrupt::Uart3Rx);
        // The simulated analogue hardware produces the next conversion (not the hand-off).
        cx.local.converter.convert();
    }

    /// The estimator task: drains the queue (bounded by its capacity) into the weighing core.
    /// Bound to UART 3's receive vector, which nothing else raises (QEMU gives UART 3 no
    /// backend): a spare vector, pended by the hand-off.
    #[task(binds = Uart3Rx, priority = 2, local = [consumer], shared = [latest, pipeline])]
    fn estimate(mut cx: estimate::Context) {
        let consumer = cx.local.consumer;
        let shared = &mut cx.shared;
        pipeline::estimate(&mut shared.pipeline, &mut shared.latest, consumer, READOUT);
    }

    /// The command task: the operator's bytes from UART 0, below the estimator's priority.
    /// Each completed line is decided against the reading at that moment; its outcome goes
    /// to the console and the log.
    #[task(binds = Uart0Rx, priority = 1, shared = [pipeline, console, store])]
    fn command(cx: command::Context) {
        let command::SharedResources {
            mut pipeline,
            mut console,
            mut store,
            ..
        } = cx.shared;
        let mut save = |settings: &_| store.lock(|store| pipeline::save_settings(store, settings));
        console.lock(|console| {
            for _ in 0..BYTES_PER_INTERRUPT {
                match console.port().take_byte() {
                    Ok(Some(byte)) => console.receive(byte, &mut pipeline, &mut save),
                    Ok(None) => break,
                    Err(error) => defmt::println!("command uart={} (bytes lost)", error),
                }
            }
        });
    }

    /// The readout task: 20 lines a second to the log and the console's reading lines at
    /// its rate (a final reading on both the moment it is reached); the watchdog fed while
    /// samples advance; the commands' regular work after each log line (a fresh tare
    /// refined, a calibration in progress carried on: stored, read back and applied once
    /// the known mass has settled); the end-of-scene summary and exit.
    #[task(binds = Uart1Rx, priority = 1, local = [scene_samples, scene, watchdog, noise_told: bool = false], shared = [latest, pipeline, console, store])]
    fn readout(mut cx: readout::Context) {
        let lines = cx.shared.latest.lock(core::mem::take);
        let (samples, e) = cx
            .shared
            .pipeline
            .lock(|pipeline| (pipeline.samples(), pipeline.scale_config().scale_interval_g));
        cx.local.watchdog.service(samples);
        let shared_pipeline = &mut cx.shared.pipeline;
        cx.shared.console.lock(|console| {
            for line in [lines.final_reading, lines.console].into_iter().flatten() {
                console.reading(&line, e);
            }
            console.pump_record(shared_pipeline, RECORD_LINES_PER_TICK);
            if let Some(lost) = console.newly_lost_bytes() {
                defmt::warn!("console lost_bytes={=u32} (the port gave them up)", lost);
            }
        });
        let Some(readout) = lines.log() else {
            return;
        };
        if cx
            .local
            .scene
            .overflows_stack_at()
            .is_some_and(|at| readout.sample >= at)
        {
            defmt::println!(
                "stack-overflow scene: recursing at sample={=u32}",
                readout.sample
            );
            let _ = qemu::exhaust_stack(0);
        }
        // Once: from here on every new run is checked against the metered empty pan.
        if !*cx.local.noise_told && cx.shared.pipeline.lock(|pipeline| pipeline.noise_checked()) {
            defmt::println!("noise metered sample={=u32}", readout.sample);
            *cx.local.noise_told = true;
        }
        if let Some(result) = cx.shared.pipeline.lock(|pipeline| pipeline.poll_commands()) {
            let shared_pipeline = &mut cx.shared.pipeline;
            let end = cx.shared.store.lock(|store| {
                pipeline::finish_calibration(result, store, |work| {
                    shared_pipeline.lock(|pipeline| work(pipeline))
                })
            });
            cx.shared
                .console
                .lock(|console| console.calibration_ended(&end));
        }
        if readout.sample >= *cx.local.scene_samples {
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
    /// figure is one long measurement instead of many one-tick ones. They run on the
    /// application's pipeline and restart it at the end.
    #[cfg(feature = "bench")]
    #[inline(never)]
    fn run_benchmarks(
        mut syst: cortex_m::peripheral::SYST,
        pipeline: &mut Pipeline,
        store: &mut QemuCalibrationStore,
        calibration: &estimator_core::weighing::Calibration,
        init_sp: u32,
    ) {
        bench::start(&mut syst);
        let iterations = 100_000;
        let (short, long) = bench::calibrate(iterations);
        defmt::println!(
            "bench calibration instructions={=u32} short={=u32} long={=u32}",
            2 * iterations,
            short,
            long
        );
        bench_handoff();

        let mut converter = SimulatedConverter::new(qemu_scenes::demo_scene());
        // 100 ms of samples per measurement: small enough to sit on the init stack next to a
        // model bank's scale (20 KB) and the converter.
        let mut chunk = [SampleMessage {
            sequence: 0,
            sample: RawSample::Lost,
        }; 400];
        let sequence = bench_demo(pipeline, &mut converter, &mut chunk);
        bench_restart(pipeline, &mut converter, sequence);
        pipeline.restart();
        bench_checked_demo(pipeline, &mut chunk);
        pipeline.restart();
        bench_coloured_demo(pipeline, &mut chunk);
        pipeline.restart();

        // The deepest the stack went since `init` began: the factory calibration, building
        // the configured scale, the replay above. (Before the task stacks, which paint the
        // stack again.)
        let (used, size) = bench::stack_used();
        defmt::println!("bench stack used={=u32} size={=u32}", used, size);
        bench_task_stacks(pipeline, &mut chunk, store, calibration, init_sp);
        pipeline.restart();
    }

    /// Each priority's deepest stack, its task bodies run from here on a painted stack:
    /// the hand-off (3); the estimator task over the demo scene (2); the readout (1: the
    /// lines logged, the commands polled, a calibration stored) and the command task (1:
    /// a tare decided and logged), which cannot preempt each other; and what `idle` stands
    /// on (the stack at `init`'s entry). `cargo xtask bench` adds them up with the
    /// exception frames of the three preemptions.
    #[cfg(feature = "bench")]
    fn bench_task_stacks(
        pipeline: &mut Pipeline,
        chunk: &mut [SampleMessage],
        store: &mut QemuCalibrationStore,
        calibration: &estimator_core::weighing::Calibration,
        init_sp: u32,
    ) {
        let handoff = bench::handoff_stack();
        let mut converter = SimulatedConverter::new(qemu_scenes::demo_scene());
        // The QEMU board's hand-off also steps the simulated analogue chain.
        let model = bench::stack_depth_of(|| converter.convert());
        let mut latest = Lines::default();
        let mut sequence = 0u32;
        let mut estimator = 0;
        for _ in 0..(4 * SAMPLE_RATE_HZ) as usize / chunk.len() {
            converter.fill(chunk, &mut sequence);
            estimator = estimator.max(bench::estimator_stack(
                pipeline,
                &mut latest,
                chunk,
                Interrupt::Uart2Rx,
            ));
        }
        // Uart2Rx is never enabled: the pends above only stand for the readout's.
        cortex_m::peripheral::NVIC::unpend(Interrupt::Uart2Rx);
        // The console's formatting, on a port that discards the bytes (its depth is the
        // writing's, not the UART's).
        let mut console = Console::new(bench::Discard);
        let e = pipeline.scale_config().scale_interval_g;
        // The lines taken into the task's own frame, as the task takes them; each console
        // reading line written, then the log's.
        let log = bench::stack_depth_of(|| {
            let lines = core::hint::black_box(core::mem::take(&mut latest));
            for line in [lines.final_reading, lines.console].into_iter().flatten() {
                console.reading(&line, e);
            }
            let _ = lines.log();
        });
        let poll = bench::stack_depth_of(|| {
            let _ = pipeline.poll_commands();
        });
        let store_calibration = bench::stack_depth_of(|| {
            let end = pipeline::finish_calibration(Ok(*calibration), store, |work| work(pipeline));
            console.calibration_ended(&end);
        });
        // The deepest commands: a tare decided and answered, the whole configuration listed,
        // a setting changed and stored (each typed as a line, ended by its CR).
        let mut command = 0;
        let mut save = |settings: &_| pipeline::save_settings(store, settings);
        for line in [
            &b"tare\r"[..],
            b"config show\r",
            b"config set capacity_g 600\r",
        ] {
            command = command.max(bench::stack_depth_of(|| {
                for &byte in line {
                    console.receive(byte, &mut bench::Unshared(&mut *pipeline), &mut save);
                }
            }));
        }
        let (_, top) = fault::stack_bounds();
        defmt::println!(
            "bench task stacks idle={=u32} handoff={=u32} estimator={=u32} readout={=u32} command={=u32}",
            top - init_sp,
            handoff.max(model),
            estimator,
            log.max(poll).max(store_calibration),
            command
        );
    }

    /// The hand-off with the timer's acknowledge and the pend of the estimator task.
    #[cfg(feature = "bench")]
    fn bench_handoff() {
        // Safety: timer 1 is not used by the application; this is its only handle.
        let mut spare_timer = unsafe { CmsdkTimer::timer1() };
        let (ticks, events) = bench::measure_handoff(100, || {
            spare_timer.clear_interrupt();
            rtic::pend(Interrupt::Uart2Rx);
        });
        // Uart2Rx is never enabled, so the pend only costs what the real one costs.
        cortex_m::peripheral::NVIC::unpend(Interrupt::Uart2Rx);
        defmt::println!("bench handoff ticks={=u64} events={=u32}", ticks, events);
    }

    /// The demo scene through the pipeline, chunk by chunk; the simulated analogue chain
    /// timed apart. Returns the next sequence number.
    #[cfg(feature = "bench")]
    fn bench_demo(
        pipeline: &mut Pipeline,
        converter: &mut SimulatedConverter<LoadCell>,
        chunk: &mut [SampleMessage],
    ) -> u32 {
        let mut sequence = 0u32;
        let mut ticks = 0u64;
        let mut model_ticks = 0u64;
        for _ in 0..(4 * SAMPLE_RATE_HZ) as usize / chunk.len() {
            let model_start = bench::now();
            converter.fill(chunk, &mut sequence);
            model_ticks += bench::since(model_start) as u64;
            let work = bench::measure_pipeline(pipeline, chunk);
            let overhead = bench::measure_loop_overhead(chunk);
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
        sequence
    }

    /// A restart (what a load change or a lost sample costs once): the sample after a lost
    /// one resets the estimator before it is pushed. Timed on the samples that follow the
    /// scene, the same push without the reset is not subtracted (it is a few hundred
    /// instructions against the reset's thousands for a bank).
    #[cfg(feature = "bench")]
    fn bench_restart(
        pipeline: &mut Pipeline,
        converter: &mut SimulatedConverter<LoadCell>,
        mut sequence: u32,
    ) {
        use estimator_core::sensor::AdcSource;
        let mut restart_ticks = 0u64;
        let restarts = 8u32;
        for _ in 0..restarts {
            pipeline.samples_lost(1);
            let sample = match converter.read() {
                Ok(code) => RawSample::Counts(code as i32),
                Err(_) => RawSample::Lost,
            };
            converter.convert();
            let message = [SampleMessage { sequence, sample }];
            sequence += 1;
            let work = bench::measure_pipeline(pipeline, &message);
            restart_ticks += work.saturating_sub(bench::measure_loop_overhead(&message));
        }
        defmt::println!(
            "bench restart ticks={=u64} events={=u32}",
            restart_ticks,
            restarts
        );
    }

    /// The consistency check live: the checked demo (the demo after more empty pan), so the
    /// drops land after a metered empty period; timed from the first drop on, the checked
    /// runs. The restarted pipeline counts sequence numbers from zero again.
    #[cfg(feature = "bench")]
    fn bench_checked_demo(pipeline: &mut Pipeline, chunk: &mut [SampleMessage]) {
        bench_demo_after_empty(
            pipeline,
            chunk,
            qemu_scenes::CHECKED_DEMO_EMPTY_S,
            "checked",
            Pipeline::noise_checked,
        );
    }

    /// The step method's `u` on the empty pan's noise colour: the demo after long enough
    /// an empty pan for the colour to be metered, timed from the first drop on.
    #[cfg(feature = "bench")]
    fn bench_coloured_demo(pipeline: &mut Pipeline, chunk: &mut [SampleMessage]) {
        bench_demo_after_empty(
            pipeline,
            chunk,
            qemu_scenes::COLOURED_DEMO_EMPTY_S,
            "coloured",
            Pipeline::noise_coloured,
        );
    }

    /// The demo after `empty_s` more of empty pan, timed from its first drop on for 3 s:
    /// `bench <label> ticks= events= metered= dropped=`, `metered` whether `live` held at
    /// the drop.
    #[cfg(feature = "bench")]
    fn bench_demo_after_empty(
        pipeline: &mut Pipeline,
        chunk: &mut [SampleMessage],
        empty_s: f64,
        label: &str,
        live: fn(&Pipeline) -> bool,
    ) {
        let mut converter =
            SimulatedConverter::new(qemu_scenes::demo_scene_with_empty_start(empty_s));
        let first_drop_s = empty_s + host_sim::simulated::REFERENCE_DEMO_EVENTS[0].time_s;
        // Rounded to the nearest sample, as the script places the drop.
        let first_drop_chunk = (first_drop_s * SAMPLE_RATE_HZ as f64 + 0.5) as usize / chunk.len();
        let mut sequence = 0u32;
        let mut timed_ticks = 0u64;
        let mut timed_events = 0u32;
        let mut metered = false;
        let end_s = empty_s + 3.0;
        for index in 0..(end_s * SAMPLE_RATE_HZ as f64) as usize / chunk.len() {
            converter.fill(chunk, &mut sequence);
            if index + 1 == first_drop_chunk {
                metered = live(pipeline);
            }
            let work = bench::measure_pipeline(pipeline, chunk);
            if index >= first_drop_chunk {
                let overhead = bench::measure_loop_overhead(chunk);
                timed_ticks += work.saturating_sub(overhead);
                timed_events += chunk.len() as u32;
            }
        }
        defmt::println!(
            "bench {=str} ticks={=u64} events={=u32} metered={=u32} dropped={=u32}",
            label,
            timed_ticks,
            timed_events,
            metered as u32,
            pipeline.dropped()
        );
    }
}

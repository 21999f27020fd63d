//! The weighing firmware on an STM32F411: TIM2 triggers ADC1 at 4 kHz, DMA2 stream 0
//! double-buffers the conversions, the hand-off moves each finished buffer into the queue,
//! the estimator task runs the weighing core, and the readout goes out over RTT (defmt) and
//! on the serial console, a USB CDC port on the OTG FS connector (`firmware::console`: the
//! same lines and commands as the QEMU board's UART). The KEY button (PA0) gives the
//! operator's commands too: a short press tares, a long press (2 s or more) calibrates with
//! the reference mass, a short press during a calibration cancels it; the record goes to
//! flash sectors 6–7 (power-fail safe).
//!
//! Built with feature `ads131m02`, an external ADS131M02 on SPI1 converts instead: its DRDY
//! edge (EXTI3) runs the hand-off, which reads one frame and queues its sample the same way.
#![no_std]
#![no_main]

use defmt_rtt as _;

#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true)]
mod app {
    use cortex_m::peripheral::DWT;
    use estimator_core::weighing::{Command, KeyDebouncer, KeyPress, SampleSequence};
    #[cfg(not(feature = "ads131m02"))]
    #[cfg(not(feature = "ads131m02"))]
    use estimator_core::{sensor::CodeBlock, weighing::RawSample};
    use firmware::console::Console;
    use firmware::fault;
    use firmware::pipeline::{
        self, EstimatorStorage, FirmwareRecorder, Lines, Pipeline, SampleMessage, SampleQueue,
        SampleWatchdog, QUEUE_CAPACITY, SAMPLE_RATE_HZ,
    };
    #[cfg(feature = "ads131m02")]
    use firmware::stm32f411::ads131m02 as external;
    use firmware::stm32f411::{
        self as board, CalibrationFlashStore, DrdyHandoff, UsbConsolePort, DMA_BLOCK, FRONT_END,
        KEY_DEBOUNCE_MS, KEY_LONG_PRESS_MS, KEY_POLL_HZ, REFERENCE_MASS_G, SYSCLK_HZ,
        USB_RX_BUFFER, USB_TX_BUFFER,
    };
    use heapless::spsc::{Consumer, Producer};
    // The internal converter's types name resources RTIC declares in either build.
    #[cfg(not(feature = "ads131m02"))]
    use stm32f4xx_hal::{
        adc::config::{
            AdcConfig, Dma, ExternalTrigger, Resolution, SampleTime, Sequence, TriggerMode,
        },
        dma::{config::DmaConfig, DMAError, StreamsTuple},
    };
    use stm32f4xx_hal::{
        adc::Adc,
        dma::{PeripheralToMemory, Stream0, Transfer},
        pac::{ADC1, DMA2},
    };
    use stm32f4xx_hal::{
        gpio::{gpioa::PA0, Edge, Input},
        otg_fs::{UsbBus, UsbBusType, USB},
        pac::{self, EXTI},
        prelude::*,
        rcc::{Config, Rcc},
        syscfg::SysCfg,
        timer::{CounterHz, Event, Flag},
        watchdog::IndependentWatchdog,
    };
    use usb_device::bus::UsbBusAllocator;
    use usb_device::device::{StringDescriptors, UsbDevice, UsbDeviceBuilder, UsbVidPid};

    type AdcTransfer =
        Transfer<Stream0<DMA2>, 0, Adc<ADC1>, PeripheralToMemory, &'static mut [u16; DMA_BLOCK]>;

    /// The 12-bit converter's rails.
    #[cfg(not(feature = "ads131m02"))]
    const MAX_CODE: u16 = 4095;
    /// The readout task's vector, pended by the estimator task after each readout.
    const READOUT: pac::Interrupt = pac::Interrupt::EXTI2;
    /// Words of the OTG FS endpoint memory the USB driver works in.
    const USB_ENDPOINT_WORDS: usize = 1024;
    /// `D` lines of a recording written per readout tick: about 430 bytes, which the 1 KiB
    /// USB transmit buffer holds beside reading lines and what the host has not yet taken
    /// (a line the buffer cannot take whole abandons the recording); a 1.25 s recording
    /// takes 4 s at 20 ticks a second.
    const RECORD_LINES_PER_TICK: usize = 4;
    /// Reads of the USB port per interrupt (64 bytes each): bounded, and more than its
    /// receive buffer holds.
    const USB_READS_PER_INTERRUPT: usize = 4;

    /// The KEY button and what debounces it: EXTI0 wakes on the first falling edge, then
    /// TIM3 polls the level at `KEY_POLL_HZ` until the button is released and settled.
    pub struct Key {
        pin: PA0<Input>,
        exti: EXTI,
        poll_timer: CounterHz<pac::TIM3>,
        debouncer: KeyDebouncer,
    }

    impl Key {
        /// PA0 to GND when pressed (active low, internal pull-up), falling edge on EXTI0;
        /// TIM3 interrupts only while the key is being polled.
        fn new(
            pin: PA0,
            mut exti: EXTI,
            syscfg: &mut SysCfg,
            tim3: pac::TIM3,
            rcc: &mut Rcc,
        ) -> Self {
            let mut pin = pin.into_pull_up_input();
            pin.make_interrupt_source(syscfg);
            pin.trigger_on_edge(&mut exti, Edge::Falling);
            pin.enable_interrupt(&mut exti);
            let mut poll_timer = tim3.counter_hz(rcc);
            poll_timer.listen(Event::Update);
            Self {
                pin,
                exti,
                poll_timer,
                debouncer: KeyDebouncer::new(KEY_POLL_HZ, KEY_DEBOUNCE_MS, KEY_LONG_PRESS_MS),
            }
        }
    }

    /// The config's counts (noise variance, rails) are those of the chain it was calibrated
    /// on; this board's converter is 12 bits (24 with the ADS131M02). The method and the model carry over, the
    /// bias-compensated method's noise variance does not: say so when they differ.
    fn note_config_converter() {
        let config_max_code = pipeline::config::WEIGHING.onset.rail_high;
        if config_max_code != ((1u32 << FRONT_END.adc_bits) - 1) as f64 {
            defmt::println!(
                "config note: calibrated on a converter with max code {=f32}, this board's is {=u32}: recalibrate with drops of this board (firmware/README.md)",
                config_max_code as f32,
                (1u32 << FRONT_END.adc_bits) - 1
            );
        }
    }

    #[shared]
    struct Shared {
        latest: Lines,
        pipeline: Pipeline,
        key: Key,
        console: Console<UsbConsolePort>,
        store: CalibrationFlashStore,
    }

    #[local]
    struct Local {
        #[cfg(not(feature = "ads131m02"))]
        transfer: AdcTransfer,
        #[cfg(not(feature = "ads131m02"))]
        spare: Option<&'static mut [u16; DMA_BLOCK]>,
        #[cfg(feature = "ads131m02")]
        external: DrdyHandoff,
        #[cfg(not(feature = "ads131m02"))]
        producer: Producer<'static, SampleMessage>,
        consumer: Consumer<'static, SampleMessage>,
        #[cfg(not(feature = "ads131m02"))]
        sequence: u32,
        watchdog: SampleWatchdog<IndependentWatchdog>,
        usb_device: UsbDevice<'static, UsbBusType>,
        #[cfg(not(feature = "ads131m02"))]
        _trigger: CounterHz<pac::TIM2>,
    }

    #[init(local = [
        queue: SampleQueue = SampleQueue::new(),
        #[cfg(not(feature = "ads131m02"))]
        first: [u16; DMA_BLOCK] = [0; DMA_BLOCK],
        #[cfg(not(feature = "ads131m02"))]
        second: [u16; DMA_BLOCK] = [0; DMA_BLOCK],
        #[cfg(not(feature = "ads131m02"))]
        third: [u16; DMA_BLOCK] = [0; DMA_BLOCK],
        estimator: EstimatorStorage = EstimatorStorage::UNCONFIGURED,
        recorder: FirmwareRecorder = FirmwareRecorder::new(),
        usb_endpoints: [u32; USB_ENDPOINT_WORDS] = [0; USB_ENDPOINT_WORDS],
        usb_bus: Option<UsbBusAllocator<UsbBusType>> = None,
        usb_tx: [u8; USB_TX_BUFFER] = [0; USB_TX_BUFFER],
        usb_rx: [u8; USB_RX_BUFFER] = [0; USB_RX_BUFFER],
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let device = cx.device;
        let mut core = cx.core;
        fault::guard_stack(&mut core.MPU, &mut core.SCB);
        board::log_reset_cause();
        let mut rcc = device.RCC.freeze(
            Config::hse(25.MHz())
                .sysclk(SYSCLK_HZ.Hz())
                .pclk2(84.MHz())
                .require_pll48clk(),
        );
        // The cycle counter times a calibration's flash write (see `readout`).
        core.DCB.enable_trace();
        core.DWT.enable_cycle_counter();

        let mut store = board::calibration_store(device.FLASH);
        let (calibration, source) = board::load_calibration(&mut store);
        pipeline::log_calibration(&calibration, &source);
        let scale = match pipeline::scale(calibration.counts_scale(), cx.local.estimator) {
            Ok(scale) => scale,
            Err(error) => defmt::panic!("weighing configuration refused: {}", error),
        };
        pipeline::log_config();
        note_config_converter();

        let gpioa = device.GPIOA.split(&mut rcc);
        let mut syscfg = device.SYSCFG.constrain(&mut rcc);
        #[cfg(feature = "ads131m02")]
        let mut exti = device.EXTI;
        #[cfg(not(feature = "ads131m02"))]
        let exti = device.EXTI;

        // The ADS131M02 on SPI1, each conversion announced on DRDY (PA3, EXTI3).
        #[cfg(feature = "ads131m02")]
        let (adc, drdy) = external::external_adc(
            device.SPI1,
            external::AdcPins {
                sck: gpioa.pa5,
                miso: gpioa.pa6,
                mosi: gpioa.pa7,
                cs: gpioa.pa4,
                drdy: gpioa.pa3,
            },
            &mut syscfg,
            &mut exti,
            &mut rcc,
        );

        // INA114 output on PA1 (ADC1_IN1), converted on every TIM2 update. (PA0 is the
        // Black Pill's KEY button.)
        #[cfg(not(feature = "ads131m02"))]
        let load_cell = gpioa.pa1.into_analog();
        #[cfg(not(feature = "ads131m02"))]
        let (transfer, trigger) = {
            let adc_config = AdcConfig::default()
                .resolution(Resolution::Twelve)
                .external_trigger(TriggerMode::RisingEdge, ExternalTrigger::Tim_2_trgo)
                .dma(Dma::Continuous);
            let mut adc = Adc::new(device.ADC1, true, adc_config, &mut rcc);
            adc.configure_channel(&load_cell, Sequence::One, SampleTime::Cycles_144);
            adc.enable();

            let streams = StreamsTuple::new(device.DMA2, &mut rcc);
            let dma_config = DmaConfig::default()
                .memory_increment(true)
                .double_buffer(true)
                .transfer_complete_interrupt(true);
            let mut transfer = Transfer::init_peripheral_to_memory(
                streams.0,
                adc,
                cx.local.first,
                Some(cx.local.second),
                dma_config,
            );
            transfer.start(|_adc| {});

            // TIM2 at 4 kHz with its update event as TRGO: the ADC trigger, no CPU involved.
            let mut trigger = device.TIM2.counter_hz(&mut rcc);
            if trigger.start(SAMPLE_RATE_HZ.Hz()).is_err() {
                defmt::panic!("TIM2 cannot run at {=u32} Hz", SAMPLE_RATE_HZ);
            }
            // Safety: TIM2 is owned by `trigger`; this only selects its master mode (TRGO =
            // update), a field the HAL's counter does not use.
            unsafe { (*pac::TIM2::ptr()).cr2().modify(|_, w| w.mms().update()) };
            (transfer, trigger)
        };

        let key = Key::new(gpioa.pa0, exti, &mut syscfg, device.TIM3, &mut rcc);

        // The console on USB (PA11/PA12, the board's USB-C connector): a CDC ACM serial port.
        let usb = USB::new(
            (
                device.OTG_FS_GLOBAL,
                device.OTG_FS_DEVICE,
                device.OTG_FS_PWRCLK,
            ),
            (gpioa.pa11, gpioa.pa12),
            &rcc.clocks,
        );
        let usb_bus = cx
            .local
            .usb_bus
            .insert(UsbBus::new(usb, cx.local.usb_endpoints));
        let serial = usbd_serial::SerialPort::new_with_store(
            usb_bus,
            &mut cx.local.usb_rx[..],
            &mut cx.local.usb_tx[..],
        );
        // pid.codes' test VID/PID for CDC ACM (0x16c0/0x27dd); a product needs its own.
        let strings = StringDescriptors::default()
            .manufacturer("fast-weighing")
            .product("scale console")
            .serial_number("0001");
        let usb_device = match UsbDeviceBuilder::new(usb_bus, UsbVidPid(0x16c0, 0x27dd))
            .device_class(usbd_serial::USB_CLASS_CDC)
            .strings(&[strings])
        {
            Ok(builder) => builder.build(),
            Err(_) => defmt::panic!("USB string descriptors refused"),
        };
        let mut console = Console::new(UsbConsolePort::new(serial));
        defmt::println!(
            "KEY: short press tare (or cancel a calibration), long press (>= {=u32} ms) calibrate with {=f32} g",
            KEY_LONG_PRESS_MS,
            REFERENCE_MASS_G
        );

        // Started last, so the time `init` takes does not count: from here on it resets the
        // chip unless samples keep reaching the readout task (halted with the core under a
        // debugger).
        let mut watchdog = IndependentWatchdog::new(device.IWDG);
        watchdog.stop_on_debug(&device.DBGMCU, true);
        watchdog.start(board::WATCHDOG_TIMEOUT_MS.millis());

        let mut pipeline = Pipeline::new(
            scale,
            FRONT_END.calibration_limits(),
            source,
            cx.local.recorder,
        );
        console.set_unit(pipeline::load_settings(&mut store, &mut pipeline));

        let (producer, consumer) = cx.local.queue.split();
        (
            Shared {
                latest: Lines::default(),
                pipeline,
                key,
                console,
                store,
            },
            Local {
                #[cfg(not(feature = "ads131m02"))]
                transfer,
                #[cfg(not(feature = "ads131m02"))]
                spare: Some(cx.local.third),
                #[cfg(feature = "ads131m02")]
                external: DrdyHandoff::new(adc, drdy, producer),
                #[cfg(not(feature = "ads131m02"))]
                producer,
                consumer,
                #[cfg(not(feature = "ads131m02"))]
                sequence: 0,
                watchdog: SampleWatchdog::new(watchdog, 0),
                usb_device,
                #[cfg(not(feature = "ads131m02"))]
                _trigger: trigger,
            },
        )
    }

    /// The sample hand-off: swap the finished DMA buffer for the spare one and queue its
    /// samples. A DMA overrun loses the block: its sequence numbers are skipped, so the
    /// estimator task counts every lost sample.
    #[cfg(not(feature = "ads131m02"))]
    #[task(binds = DMA2_STREAM0, priority = 3, local = [transfer, spare, producer, sequence])]
    fn sample_handoff(cx: sample_handoff::Context) {
        let Some(spare) = cx.local.spare.take() else {
            return;
        };
        match cx.local.transfer.next_transfer(spare) {
            Ok((filled, _)) => {
                // The block through the converter seam: rails and guard band as for any
                // converter.
                let mut block = CodeBlock::new(
                    &filled[..],
                    u32::from(MAX_CODE),
                    board::ADC_RAIL_GUARD_CODES,
                );
                for _ in 0..DMA_BLOCK {
                    let sample = RawSample::read(&mut block);
                    let sequence = *cx.local.sequence;
                    let _ = cx
                        .local
                        .producer
                        .enqueue(SampleMessage { sequence, sample });
                    *cx.local.sequence = sequence.wrapping_add(1);
                }
                *cx.local.spare = Some(filled);
            }
            Err(DMAError::NotReady(buffer))
            | Err(DMAError::SmallBuffer(buffer))
            | Err(DMAError::Overrun(buffer)) => {
                *cx.local.sequence = cx.local.sequence.wrapping_add(DMA_BLOCK as u32);
                *cx.local.spare = Some(buffer);
            }
        }
        rtic::pend(pac::Interrupt::EXTI1);
    }

    /// The sample hand-off of the ADS131M02 build, at its DRDY edge: one frame read through
    /// the converter seam and queued (`DrdyHandoff::hand_off`).
    #[cfg(feature = "ads131m02")]
    #[task(binds = EXTI3, priority = 3, local = [external])]
    fn drdy_handoff(cx: drdy_handoff::Context) {
        cx.local.external.hand_off();
        rtic::pend(pac::Interrupt::EXTI1);
    }

    /// The estimator task: drains the queue (bounded by its capacity) into the weighing core.
    #[task(binds = EXTI1, priority = 2, local = [consumer], shared = [latest, pipeline])]
    fn estimate(mut cx: estimate::Context) {
        let consumer = cx.local.consumer;
        let shared = &mut cx.shared;
        pipeline::estimate(&mut shared.pipeline, &mut shared.latest, consumer, READOUT);
    }

    /// The readout task: 20 lines a second over RTT and the console's reading lines; after
    /// each log line, the commands' regular work (a fresh tare refined, a calibration in
    /// progress carried on). A finished calibration is appended to the flash store (about
    /// 30 bytes), read back and applied ([`stall_counted`]: a sector erase's stall counts
    /// its lost samples).
    /// The watchdog is fed here while samples advance.
    #[task(binds = EXTI2, priority = 1, local = [watchdog], shared = [latest, pipeline, console, store])]
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
        if lines.log().is_none() {
            return;
        }
        let Some(result) = cx.shared.pipeline.lock(|pipeline| pipeline.poll_commands()) else {
            return;
        };
        let store = &mut cx.shared.store;
        let end = stall_counted(&mut cx.shared.pipeline, |shared_pipeline| {
            store.lock(|store| {
                pipeline::finish_calibration(result, store, |work| {
                    shared_pipeline.lock(|pipeline| work(pipeline))
                })
            })
        });
        cx.shared
            .console
            .lock(|console| console.calibration_ended(&end));
    }

    /// Run `work`, which may write flash (a calibration or settings record: once in
    /// thousands of writes the store erases a 128 KiB sector and the CPU stalls for 2–4 s
    /// while the converter runs on), and count the samples such a stall lost: what the
    /// converter took meanwhile minus what reached the estimator (within the queue's depth,
    /// which may still hold some).
    fn stall_counted<M: rtic::Mutex<T = Pipeline>, R>(
        pipeline: &mut M,
        work: impl FnOnce(&mut M) -> R,
    ) -> R {
        let accepted_before = pipeline.lock(|pipeline| pipeline.samples());
        let started = DWT::cycle_count();
        let result = work(pipeline);
        let elapsed_cycles = DWT::cycle_count().wrapping_sub(started);
        let converted = elapsed_cycles / (SYSCLK_HZ / SAMPLE_RATE_HZ);
        pipeline.lock(|pipeline| {
            let accepted = pipeline.samples().wrapping_sub(accepted_before);
            let lost = SampleSequence::stall_loss(converted, accepted, QUEUE_CAPACITY as u32);
            if lost > 0 {
                defmt::println!(
                    "command flash write stalled the CPU for {=u32} ms: {=u32} samples lost",
                    elapsed_cycles / (SYSCLK_HZ / 1000),
                    lost
                );
                pipeline.samples_lost(lost);
            }
        });
        result
    }

    /// The KEY's first falling edge: stop listening to edges (contact bounce would make
    /// many) and poll the level instead until the press is over.
    #[task(binds = EXTI0, priority = 1, shared = [key])]
    fn key_edge(mut cx: key_edge::Context) {
        cx.shared.key.lock(|key| {
            key.pin.clear_interrupt_pending_bit();
            key.pin.disable_interrupt(&mut key.exti);
            if key.poll_timer.start(KEY_POLL_HZ.Hz()).is_err() {
                // TIM3 cannot run at the poll rate: listen to edges again rather than
                // leave the key deaf.
                key.pin.enable_interrupt(&mut key.exti);
            }
        });
    }

    /// One poll of the KEY (TIM3): debounce; a finished press becomes a command, decided
    /// against the reading of that moment and logged; once the key is released and
    /// settled, polling stops and the edge interrupt is back.
    #[task(binds = TIM3, priority = 1, shared = [key, pipeline, console])]
    fn key_poll(mut cx: key_poll::Context) {
        let press = cx.shared.key.lock(|key| {
            key.poll_timer.clear_flags(Flag::Update);
            let press = key.debouncer.poll(key.pin.is_low());
            if key.debouncer.is_idle() {
                let _ = key.poll_timer.cancel();
                key.pin.clear_interrupt_pending_bit();
                key.pin.enable_interrupt(&mut key.exti);
                // Pressed again between the last poll and now: its edge may have come
                // before the pending bit was cleared, so keep polling instead.
                if key.pin.is_low() {
                    key.pin.disable_interrupt(&mut key.exti);
                    let _ = key.poll_timer.start(KEY_POLL_HZ.Hz());
                }
            }
            press
        });
        let Some(press) = press else {
            return;
        };
        let (sample, command, result, e) = cx.shared.pipeline.lock(|pipeline| {
            let command = match press {
                KeyPress::Short if pipeline.is_calibrating() => Command::CancelCalibration,
                KeyPress::Short => Command::Tare,
                KeyPress::Long => Command::Calibrate {
                    known_mass_g: REFERENCE_MASS_G,
                },
            };
            let result = pipeline.command(command);
            let e = pipeline.scale_config().scale_interval_g;
            (pipeline.samples(), command, result, e)
        });
        defmt::println!("key press={}", press);
        pipeline::log_command(sample, command, &result);
        cx.shared
            .console
            .lock(|console| console.answer(command, &result, e));
    }

    /// The USB device (OTG FS): every USB event is handled here, and the bytes the host
    /// sent go to the console, line by line, decided against the reading of that moment.
    #[task(binds = OTG_FS, priority = 1, local = [usb_device], shared = [console, pipeline, store])]
    fn usb_console(cx: usb_console::Context) {
        let usb_console::SharedResources {
            mut console,
            mut pipeline,
            mut store,
            ..
        } = cx.shared;
        // A changed setting goes to flash; the bytes of each read are decided inside
        // `stall_counted`, so a write that stalls the CPU counts the samples it lost.
        let mut save = |settings: &_| store.lock(|store| pipeline::save_settings(store, settings));
        let usb_device = cx.local.usb_device;
        console.lock(|console| {
            if !usb_device.poll(&mut [console.port().class()]) {
                return;
            }
            let mut buffer = [0u8; 64];
            for _ in 0..USB_READS_PER_INTERRUPT {
                let count = console.port().read(&mut buffer);
                if count == 0 {
                    break;
                }
                stall_counted(&mut pipeline, |pipeline| {
                    for &byte in &buffer[..count] {
                        console.receive(byte, pipeline, &mut save);
                    }
                });
            }
        });
    }
}

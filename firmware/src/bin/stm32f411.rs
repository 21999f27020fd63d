//! The weighing firmware on an STM32F411: TIM2 triggers ADC1 at 4 kHz, DMA2 stream 0
//! double-buffers the conversions, the hand-off moves each finished buffer into the queue,
//! the estimator task runs the weighing core, and the readout goes out over RTT (defmt).
#![no_std]
#![no_main]

use defmt_rtt as _;

#[rtic::app(device = stm32f4xx_hal::pac, peripherals = true)]
mod app {
    use estimator_core::{RawSample, Scale};
    use firmware::pipeline::{
        self, Pipeline, Readout, SampleMessage, SampleQueue, QUEUE_CAPACITY, SAMPLE_RATE_HZ,
    };
    use firmware::stm32f411::{self as board, DMA_BLOCK};
    use heapless::spsc::{Consumer, Producer};
    use stm32f4xx_hal::{
        adc::{
            config::{
                AdcConfig, Dma, ExternalTrigger, Resolution, SampleTime, Sequence, TriggerMode,
            },
            Adc,
        },
        dma::{config::DmaConfig, DMAError, PeripheralToMemory, Stream0, StreamsTuple, Transfer},
        pac::{self, ADC1, DMA2},
        prelude::*,
        rcc::Config,
        timer::CounterHz,
    };

    type AdcTransfer =
        Transfer<Stream0<DMA2>, 0, Adc<ADC1>, PeripheralToMemory, &'static mut [u16; DMA_BLOCK]>;

    /// The 12-bit converter's rails.
    const MAX_CODE: u16 = 4095;

    #[shared]
    struct Shared {
        latest: Option<Readout>,
    }

    #[local]
    struct Local {
        transfer: AdcTransfer,
        spare: Option<&'static mut [u16; DMA_BLOCK]>,
        producer: Producer<'static, SampleMessage>,
        consumer: Consumer<'static, SampleMessage>,
        pipeline: Pipeline,
        sequence: u32,
        _trigger: CounterHz<pac::TIM2>,
    }

    #[init(local = [
        queue: SampleQueue = SampleQueue::new(),
        first: [u16; DMA_BLOCK] = [0; DMA_BLOCK],
        second: [u16; DMA_BLOCK] = [0; DMA_BLOCK],
        third: [u16; DMA_BLOCK] = [0; DMA_BLOCK],
    ])]
    fn init(cx: init::Context) -> (Shared, Local) {
        let device = cx.device;
        let mut rcc = device
            .RCC
            .freeze(Config::hse(25.MHz()).sysclk(84.MHz()).pclk2(84.MHz()));

        let (calibration, source) = board::load_calibration();
        defmt::println!(
            "calibration counts_per_gram={=f32} zero_counts={=f32} source={}",
            calibration.counts_per_gram,
            calibration.zero_counts,
            source
        );
        let config = pipeline::scale_config();
        let scale = match Scale::new(config, calibration.counts_scale()) {
            Ok(scale) => scale,
            Err(error) => defmt::panic!("scale configuration refused: {}", error),
        };

        // INA114 output on PA0 (ADC1_IN0), converted on every TIM2 update.
        let gpioa = device.GPIOA.split(&mut rcc);
        let load_cell = gpioa.pa0.into_analog();
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

        let (producer, consumer) = cx.local.queue.split();
        (
            Shared { latest: None },
            Local {
                transfer,
                spare: Some(cx.local.third),
                producer,
                consumer,
                pipeline: Pipeline::new(scale),
                sequence: 0,
                _trigger: trigger,
            },
        )
    }

    /// The sample hand-off: swap the finished DMA buffer for the spare one and queue its
    /// samples. A DMA overrun loses the block: its sequence numbers are skipped, so the
    /// estimator task counts every lost sample.
    #[task(binds = DMA2_STREAM0, priority = 3, local = [transfer, spare, producer, sequence])]
    fn sample_handoff(cx: sample_handoff::Context) {
        let Some(spare) = cx.local.spare.take() else {
            return;
        };
        match cx.local.transfer.next_transfer(spare) {
            Ok((filled, _)) => {
                for &code in filled.iter() {
                    let sample = if code == 0 || code >= MAX_CODE {
                        RawSample::Saturated
                    } else {
                        RawSample::Counts(code as i32)
                    };
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

    /// The estimator task: drains the queue (bounded by its capacity) into the weighing core.
    #[task(binds = EXTI1, priority = 2, local = [consumer, pipeline], shared = [latest])]
    fn estimate(mut cx: estimate::Context) {
        for _ in 0..QUEUE_CAPACITY {
            let Some(message) = cx.local.consumer.dequeue() else {
                break;
            };
            if let Some(readout) = cx.local.pipeline.accept(message) {
                cx.shared.latest.lock(|latest| *latest = Some(readout));
                rtic::pend(pac::Interrupt::EXTI2);
            }
        }
    }

    /// The readout task: 20 lines a second over RTT.
    #[task(binds = EXTI2, priority = 1, shared = [latest])]
    fn readout(mut cx: readout::Context) {
        if let Some(readout) = cx.shared.latest.lock(|latest| latest.take()) {
            pipeline::log_readout(&readout);
        }
    }
}

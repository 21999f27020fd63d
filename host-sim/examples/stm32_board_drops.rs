//! Calibration drops on the simulated 12-bit chain of the STM32 board (INA114 at gain 385.6,
//! 100 Hz Butterworth, ADC1 at 12 bits with its own noise: `host_sim::stm32_board`), as CSV
//! files `host-sim calibrate` reads (a column `y` of codes): the empty pan for 0.3 s, then
//! the 138.32 g reference mass lands and stays 1.5 s (the `calibration-drop` scene's script),
//! with only the chain's own noise.
//!
//! `cargo run --release -p host-sim --example stm32_board_drops -- DIR [COUNT]` writes
//! DIR/d1.csv … DIR/dCOUNT.csv (3 by default), seeds 1 to COUNT.

use std::io::Write;
use std::path::PathBuf;

use anyhow::{anyhow, bail, Context, Result};
use estimator_core::sensor::AdcSource;
use host_sim::stm32_board::{Stm32BoardAdc, Stm32BoardChain};
use host_sim::{Disturbances, LoadEvent, Script, SAMPLE_RATE_HZ};

const EMPTY_S: f64 = 0.3;
const MASS_G: f64 = 138.32;
const DURATION_S: f64 = 1.8;

fn main() -> Result<()> {
    let mut args = std::env::args().skip(1);
    let Some(dir) = args.next().map(PathBuf::from) else {
        bail!("usage: stm32_board_drops DIR [COUNT]");
    };
    let count: u64 = match args.next() {
        Some(count) => count.parse().context("COUNT must be a whole number")?,
        None => 3,
    };
    std::fs::create_dir_all(&dir).with_context(|| format!("create {}", dir.display()))?;
    let board = Stm32BoardChain::reference();
    for seed in 1..=count {
        let mut script = Script::<2>::new(DURATION_S);
        script
            .push(LoadEvent::step(EMPTY_S, MASS_G))
            .map_err(|error| anyhow!("script refused: {error:?}"))?;
        let mut adc = Stm32BoardAdc::new(board, script, Disturbances::none(), seed);
        let path = dir.join(format!("d{seed}.csv"));
        let mut out = std::io::BufWriter::new(
            std::fs::File::create(&path).with_context(|| format!("create {}", path.display()))?,
        );
        writeln!(out, "y")?;
        for _ in 0..(DURATION_S * SAMPLE_RATE_HZ) as usize {
            match adc.read() {
                Ok(code) => writeln!(out, "{code}")?,
                Err(error) => bail!("{}: conversion failed: {error:?}", path.display()),
            }
        }
        out.flush()?;
        eprintln!("{}", path.display());
    }
    eprintln!(
        "chain: {:.3} counts/g, zero {:.0}, converter noise {:.4} g per sample; calibrate with --adc-bits 12",
        board.counts_per_gram(),
        board.zero_code(),
        board.adc_noise_g()
    );
    Ok(())
}

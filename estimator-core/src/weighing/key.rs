//! The debouncer of the hardware board's KEY button: raw levels polled at a fixed rate in,
//! one [`KeyPress`] per press out.
//!
//! Contact bounce and glitches shorter than the debounce time must never make a press.

/// A debounced press of a push button.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum KeyPress {
    /// Released before the long-press time.
    Short,
    /// Held at least the long-press time.
    Long,
}

/// A push-button debouncer polled at a fixed rate (Ganssle's integrator): the raw level
/// moves a counter between 0 and `settle_polls`, and the debounced state only flips at the
/// ends, so contact bounce and glitches shorter than the settle time never make a press.
/// The press is reported on release, as short or long by how long it was held. Polling
/// only while the button is active is the board's business ([`KeyDebouncer::is_idle`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KeyDebouncer {
    settle_polls: u16,
    long_press_polls: u32,
    integrator: u16,
    pressed: bool,
    held_polls: u32,
}

impl KeyDebouncer {
    /// A debouncer polled at `poll_hz`; the level must hold for `debounce_ms` to count, a
    /// press held `long_press_ms` or longer is long. At least one poll each.
    pub fn new(poll_hz: u32, debounce_ms: u32, long_press_ms: u32) -> Self {
        let polls = |ms: u32| ((ms as u64 * poll_hz as u64).div_ceil(1000)).max(1);
        Self {
            settle_polls: polls(debounce_ms).min(u16::MAX as u64) as u16,
            long_press_polls: polls(long_press_ms).min(u32::MAX as u64) as u32,
            integrator: 0,
            pressed: false,
            held_polls: 0,
        }
    }

    /// One poll of the raw level (`true` = pressed). `Some` when a press ends.
    pub fn poll(&mut self, raw_pressed: bool) -> Option<KeyPress> {
        if raw_pressed {
            self.integrator = (self.integrator + 1).min(self.settle_polls);
        } else {
            self.integrator = self.integrator.saturating_sub(1);
        }
        if self.pressed {
            self.held_polls = self.held_polls.saturating_add(1);
            if self.integrator == 0 {
                self.pressed = false;
                return Some(if self.held_polls >= self.long_press_polls {
                    KeyPress::Long
                } else {
                    KeyPress::Short
                });
            }
        } else if self.integrator == self.settle_polls {
            self.pressed = true;
            self.held_polls = 0;
        }
        None
    }

    /// True when the button is released and settled: nothing to poll for until it moves.
    pub fn is_idle(&self) -> bool {
        !self.pressed && self.integrator == 0
    }

    /// True while a debounced press is held.
    pub fn is_pressed(&self) -> bool {
        self.pressed
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    /// Polls at 100 Hz, 30 ms debounce, 2 s long press.
    fn debouncer() -> KeyDebouncer {
        KeyDebouncer::new(100, 30, 2000)
    }

    fn feed(key: &mut KeyDebouncer, levels: &[bool]) -> std::vec::Vec<KeyPress> {
        levels.iter().filter_map(|&level| key.poll(level)).collect()
    }

    #[test]
    fn a_bouncing_short_press_is_one_short_press() {
        let mut key = debouncer();
        assert!(key.is_idle());
        let mut levels = std::vec![true, false, true, false, true];
        levels.extend([true; 30]);
        levels.extend([false, true, false]);
        levels.extend([false; 10]);
        assert_eq!(feed(&mut key, &levels), [KeyPress::Short]);
        assert!(key.is_idle());
    }

    #[test]
    fn a_glitch_shorter_than_the_debounce_time_is_no_press() {
        let mut key = debouncer();
        assert!(feed(&mut key, &[true, true, false, false, false, false]).is_empty());
        assert!(key.is_idle());
        assert!(!key.is_pressed());
    }

    #[test]
    fn long_press_starts_at_two_seconds_of_holding() {
        // Press and release are both debounced by 3 polls, so the held time counted from
        // one to the other is the raw press: 199 polls (1.99 s) short, 200 long.
        let mut key = debouncer();
        let mut just_short = std::vec![true; 199];
        just_short.extend([false; 3]);
        assert_eq!(feed(&mut key, &just_short), [KeyPress::Short]);
        let mut long = std::vec![true; 200];
        long.extend([false; 3]);
        assert_eq!(feed(&mut key, &long), [KeyPress::Long]);
        assert!(key.is_idle());
    }

    #[test]
    fn debounce_times_round_up_to_at_least_one_poll() {
        let key = KeyDebouncer::new(100, 0, 0);
        assert_eq!(key.settle_polls, 1);
        assert_eq!(key.long_press_polls, 1);
        let key = KeyDebouncer::new(100, 25, 2001);
        assert_eq!(key.settle_polls, 3);
        assert_eq!(key.long_press_polls, 201);
    }
}

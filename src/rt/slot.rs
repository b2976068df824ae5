//! A lock-free latest-value slot: one thread publishes, the tick reads the newest value.
//!
//! Built on crossbeam's `ArrayQueue` of capacity one: `force_push` replaces whatever is there
//! (lock-free, no allocation), `pop` takes it. The reader keeps the last value it took, so a tick
//! that finds the slot empty still sees the newest state and can tell it is not fresh.
//!
//! A second, independent reader ([`SlotReader::tap`]) sees every value too: the session keeps one
//! to watch the arm's reports after the loop (the stop supervisor) while the tick owns the first.

use crossbeam::queue::ArrayQueue;
use std::sync::Arc;

/// The publishing side; cheap to clone.
#[derive(Debug)]
pub struct LatestSlot<T> {
    queue: Arc<ArrayQueue<T>>,
    tap: Arc<ArrayQueue<T>>,
}

impl<T> Clone for LatestSlot<T> {
    fn clone(&self) -> Self {
        Self { queue: Arc::clone(&self.queue), tap: Arc::clone(&self.tap) }
    }
}

impl<T: Copy> LatestSlot<T> {
    /// A slot and the reader that the tick owns.
    pub fn new() -> (Self, SlotReader<T>) {
        let queue = Arc::new(ArrayQueue::new(1));
        let tap = Arc::new(ArrayQueue::new(1));
        (
            Self { queue: Arc::clone(&queue), tap: Arc::clone(&tap) },
            SlotReader { queue, tap, last: None },
        )
    }

    /// Publish a value, replacing any the readers have not taken yet (lock-free, no allocation).
    pub fn publish(&self, value: T) {
        let _ = self.queue.force_push(value);
        let _ = self.tap.force_push(value);
    }
}

/// The reading side, owned by one thread.
#[derive(Debug)]
pub struct SlotReader<T> {
    queue: Arc<ArrayQueue<T>>,
    tap: Arc<ArrayQueue<T>>,
    last: Option<T>,
}

impl<T: Copy> SlotReader<T> {
    /// The second reader: it sees every published value independently of this one. There is one
    /// tap per slot; two taps would take values from each other.
    pub fn tap(&self) -> SlotReader<T> {
        SlotReader { queue: Arc::clone(&self.tap), tap: Arc::clone(&self.tap), last: None }
    }

    /// The newest value, and whether it arrived since the previous call.
    pub fn latest(&mut self) -> (Option<T>, bool) {
        match self.queue.pop() {
            Some(v) => {
                self.last = Some(v);
                (self.last, true)
            }
            None => (self.last, false),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reader_sees_newest_and_knows_freshness() {
        let (slot, mut reader) = LatestSlot::<u32>::new();
        assert_eq!(reader.latest(), (None, false));
        slot.publish(1);
        slot.publish(2);
        assert_eq!(reader.latest(), (Some(2), true));
        assert_eq!(reader.latest(), (Some(2), false));
        let other = slot.clone();
        other.publish(3);
        assert_eq!(reader.latest(), (Some(3), true));
    }

    #[test]
    fn the_tap_sees_every_value_independently() {
        let (slot, mut reader) = LatestSlot::<u32>::new();
        let mut tap = reader.tap();
        slot.publish(1);
        assert_eq!(reader.latest(), (Some(1), true));
        assert_eq!(tap.latest(), (Some(1), true));
        slot.publish(2);
        assert_eq!(tap.latest(), (Some(2), true));
        assert_eq!(tap.latest(), (Some(2), false));
        assert_eq!(reader.latest(), (Some(2), true));
    }
}

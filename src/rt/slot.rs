//! A lock-free latest-value slot: one thread publishes, the tick reads the newest value.
//!
//! Built on crossbeam's `ArrayQueue` of capacity one: `force_push` replaces whatever is there
//! (lock-free, no allocation), `pop` takes it. The reader keeps the last value it took, so a tick
//! that finds the slot empty still sees the newest state and can tell it is not fresh.

use crossbeam::queue::ArrayQueue;
use std::sync::Arc;

/// The publishing side; cheap to clone.
#[derive(Debug)]
pub struct LatestSlot<T> {
    queue: Arc<ArrayQueue<T>>,
}

impl<T> Clone for LatestSlot<T> {
    fn clone(&self) -> Self {
        Self { queue: Arc::clone(&self.queue) }
    }
}

impl<T: Copy> LatestSlot<T> {
    /// A slot and the reader that the tick owns.
    pub fn new() -> (Self, SlotReader<T>) {
        let queue = Arc::new(ArrayQueue::new(1));
        (Self { queue: Arc::clone(&queue) }, SlotReader { queue, last: None })
    }

    /// Publish a value, replacing any the reader has not taken yet.
    pub fn publish(&self, value: T) {
        let _ = self.queue.force_push(value);
    }
}

/// The reading side, owned by one thread.
#[derive(Debug)]
pub struct SlotReader<T> {
    queue: Arc<ArrayQueue<T>>,
    last: Option<T>,
}

impl<T: Copy> SlotReader<T> {
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
}

//! The queue between zenoh's callbacks and the caller: bounded in messages and in bytes, the
//! oldest dropped first. A caller that falls behind (or never reads) holds at most `max_bytes`,
//! and keeps the newest messages, which are the ones worth drawing.

use std::collections::VecDeque;
use std::sync::Mutex;

use tokio::sync::Notify;

struct Inner<T> {
    items: VecDeque<(T, usize)>,
    bytes: usize,
    dropped: u64,
    closed: bool,
}

pub(crate) struct BoundedQueue<T> {
    inner: Mutex<Inner<T>>,
    ready: Notify,
    max_items: usize,
    max_bytes: usize,
}

/// What a push did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Pushed {
    /// The message was queued (false: alone it is larger than the bound).
    pub queued: bool,
    /// Messages dropped to make room (or this one, when not queued).
    pub dropped: u64,
}

impl<T> BoundedQueue<T> {
    pub fn new(max_items: usize, max_bytes: usize) -> Self {
        Self {
            inner: Mutex::new(Inner { items: VecDeque::new(), bytes: 0, dropped: 0, closed: false }),
            ready: Notify::new(),
            max_items: max_items.max(1),
            max_bytes,
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner<T>> {
        // A panic while holding the lock leaves a consistent VecDeque: keep going.
        self.inner.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Queues `item` of `bytes`, dropping the oldest until it fits.
    pub fn push(&self, item: T, bytes: usize) -> Pushed {
        let mut q = self.lock();
        if bytes > self.max_bytes {
            q.dropped += 1;
            return Pushed { queued: false, dropped: 1 };
        }
        let mut dropped = 0;
        while q.items.len() >= self.max_items || q.bytes + bytes > self.max_bytes {
            let Some((_, b)) = q.items.pop_front() else { break };
            q.bytes -= b;
            dropped += 1;
        }
        q.items.push_back((item, bytes));
        q.bytes += bytes;
        q.dropped += dropped;
        drop(q);
        // One consumer: a stored permit wakes it even if it is not waiting yet.
        self.ready.notify_one();
        Pushed { queued: true, dropped }
    }

    pub fn try_pop(&self) -> Option<T> {
        let mut q = self.lock();
        let (item, b) = q.items.pop_front()?;
        q.bytes -= b;
        Some(item)
    }

    /// The next item; None once closed and empty.
    pub async fn pop(&self) -> Option<T> {
        loop {
            {
                let mut q = self.lock();
                if let Some((item, b)) = q.items.pop_front() {
                    q.bytes -= b;
                    return Some(item);
                }
                if q.closed {
                    return None;
                }
            }
            self.ready.notified().await;
        }
    }

    pub fn close(&self) {
        self.lock().closed = true;
        self.ready.notify_one();
    }

    /// Bytes held now.
    pub fn bytes(&self) -> usize {
        self.lock().bytes
    }

    pub fn dropped(&self) -> u64 {
        self.lock().dropped
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn the_oldest_go_first_and_the_bytes_stay_bounded() {
        let q = BoundedQueue::new(100, 1000);
        for i in 0..10 {
            assert_eq!(q.push(i, 300), Pushed { queued: true, dropped: u64::from(i >= 3) });
            assert!(q.bytes() <= 1000);
        }
        assert_eq!((q.bytes(), q.dropped()), (900, 7));
        assert_eq!([q.try_pop(), q.try_pop(), q.try_pop(), q.try_pop()], [Some(7), Some(8), Some(9), None]);
        assert_eq!(q.push(99, 1001), Pushed { queued: false, dropped: 1 });
        assert_eq!((q.bytes(), q.dropped()), (0, 8));
        let q = BoundedQueue::new(2, 1000);
        for i in 0..5 {
            q.push(i, 1);
        }
        assert_eq!((q.try_pop(), q.try_pop(), q.try_pop()), (Some(3), Some(4), None));
    }

    #[tokio::test]
    async fn pop_waits_for_a_push_and_ends_when_closed() {
        let q = std::sync::Arc::new(BoundedQueue::new(4, 100));
        let waiter = tokio::spawn({
            let q = q.clone();
            async move { (q.pop().await, q.pop().await) }
        });
        tokio::task::yield_now().await;
        q.push(5u8, 1);
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
        q.close();
        assert_eq!(waiter.await.unwrap(), (Some(5), None));
    }
}

//! The robot's map tiles on their way to the link: newest version per tile, sent from a task of
//! their own. Tiles may wait on a congested link (they are never dropped there), so they must
//! not be sent from the loop that runs the LIO and detection; and while they wait, a tile that
//! changed again replaces its older version instead of queueing behind it.

use starc_pipeline::link::map_tile_id;
use std::collections::BTreeMap;
use std::sync::{Mutex, MutexGuard};
use tokio::sync::Notify;

type TileKey = (i32, i32, i32);

#[derive(Default)]
struct Held {
    tiles: BTreeMap<TileKey, Vec<u8>>,
    /// Tiles without a readable key, in order (the link refuses them and counts the error).
    unkeyed: Vec<Vec<u8>>,
    closed: bool,
    superseded: u64,
}

/// Latest-wins tiles between the map thread and the tile task.
#[derive(Default)]
pub struct LatestTiles {
    held: Mutex<Held>,
    ready: Notify,
}

impl LatestTiles {
    fn lock(&self) -> MutexGuard<'_, Held> {
        self.held.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Hands over encoded tiles; an unsent older version of the same tile is replaced.
    pub fn put(&self, tiles: Vec<Vec<u8>>) {
        if tiles.is_empty() {
            return;
        }
        let mut held = self.lock();
        for bytes in tiles {
            match map_tile_id(&bytes) {
                Some((key, _)) => {
                    if held.tiles.insert(key, bytes).is_some() {
                        held.superseded += 1;
                    }
                }
                None => held.unkeyed.push(bytes),
            }
        }
        drop(held);
        self.ready.notify_one();
    }

    /// No more tiles will come: `next` returns `None` once the held ones are taken.
    pub fn close(&self) {
        self.lock().closed = true;
        self.ready.notify_one();
    }

    /// Tiles that were replaced by a newer version before they went out.
    pub fn superseded(&self) -> u64 {
        self.lock().superseded
    }

    /// The next tile to send, waiting for one; `None` once closed and empty.
    pub async fn next(&self) -> Option<Vec<u8>> {
        loop {
            let notified = self.ready.notified();
            {
                let mut held = self.lock();
                if let Some(bytes) = held.unkeyed.pop() {
                    return Some(bytes);
                }
                if let Some((_, bytes)) = held.tiles.pop_first() {
                    return Some(bytes);
                }
                if held.closed {
                    return None;
                }
            }
            notified.await;
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use starc_pipeline::align::encode_tiles;

    /// The tile of a 1 m grid holding the point (x + 0.5, 0.5, 0.5).
    fn tile(x: i32, version: u32) -> Vec<u8> {
        let p = Vector3::new(f64::from(x) + 0.5, 0.5, 0.5);
        let mut tiles = encode_tiles(&[p], &[None], 1.0, 0.05, version).unwrap();
        tiles.pop().unwrap().1
    }

    #[tokio::test]
    async fn a_tile_that_changes_while_waiting_goes_out_once_in_its_newest_version() {
        let tiles = LatestTiles::default();
        tiles.put(vec![tile(1, 1), tile(2, 1)]);
        tiles.put(vec![tile(1, 2), tile(1, 3)]);
        tiles.close();
        let mut out = Vec::new();
        while let Some(bytes) = tiles.next().await {
            out.push(map_tile_id(&bytes).unwrap());
        }
        assert_eq!(out, vec![((1, 0, 0), 3), ((2, 0, 0), 1)]);
        assert_eq!(tiles.superseded(), 2);
    }

    #[tokio::test]
    async fn next_waits_for_a_tile_and_ends_on_close() {
        let tiles = std::sync::Arc::new(LatestTiles::default());
        let reader = tokio::spawn({
            let tiles = tiles.clone();
            async move {
                let mut n = 0;
                while tiles.next().await.is_some() {
                    n += 1;
                }
                n
            }
        });
        tokio::task::yield_now().await;
        tiles.put(vec![tile(5, 1)]);
        tiles.close();
        assert_eq!(reader.await.unwrap(), 1);
    }
}

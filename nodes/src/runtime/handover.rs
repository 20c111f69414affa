//! The in-process hand-over between components of one process (`lwr_control`): the newest value of a
//! stream, put by one thread and taken by another. Nothing is allocated and nobody waits on the other's
//! work: the lock is held for a copy.

use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;

use nalgebra::{Isometry3, Vector3};

/// The newest value of a stream (`None` until the first, or after it was withdrawn).
#[derive(Debug, Default)]
pub struct Latest<T: Copy>(Mutex<Option<T>>);

impl<T: Copy> Latest<T> {
    pub fn shared() -> Arc<Self> {
        Arc::new(Self(Mutex::new(None)))
    }

    pub fn put(&self, value: T) {
        *self.lock() = Some(value);
    }

    /// The value is no longer valid (e.g. the sensor withholds an invalid sample).
    pub fn withdraw(&self) {
        *self.lock() = None;
    }

    pub fn get(&self) -> Option<T> {
        *self.lock()
    }

    /// A panicking writer cannot have left a torn `Option<T: Copy>` behind: the value is still whole.
    fn lock(&self) -> MutexGuard<'_, Option<T>> {
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// The F/T node's compensated force (/ft_sensor/wrench's force), in the sensor frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ForceReading {
    /// The sensor node's stamp \[s\].
    pub stamp: f64,
    pub force: Vector3<f64>,
    /// When the record arrived.
    pub arrived: Instant,
}

/// The driver's newest tool pose (/lwr/ee_pose), for the F/T node's gravity compensation and tare checks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolPose {
    pub pose: Isometry3<f64>,
    pub measured: Instant,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_newest_value_wins_and_a_withdrawn_one_is_gone() {
        let slot = Latest::<u32>::shared();
        assert_eq!(slot.get(), None);
        slot.put(1);
        slot.put(2);
        assert_eq!(slot.get(), Some(2));
        assert_eq!(slot.get(), Some(2), "reading does not take it away");
        slot.withdraw();
        assert_eq!(slot.get(), None);
        // Across threads, and after a writer that panicked while holding the lock.
        let writer = slot.clone();
        let _ = std::thread::spawn(move || {
            let _guard = writer.0.lock().unwrap();
            panic!("a writer dies holding the lock");
        })
        .join();
        slot.put(7);
        assert_eq!(slot.get(), Some(7));
    }
}

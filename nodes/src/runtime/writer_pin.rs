//! Which DDS writer a node takes an arm-steering stream from: one, pinned by its GUID.
//!
//! A topic has no owner in DDS: any publisher on the domain with the right name and type is matched, and
//! its samples arrive beside the real ones. On the topics that steer the arm (the driver's
//! /lwr/joint_torque_command; the separate controller's joint states, wrenches and external torques) a
//! second writer must not be heard: an adversarial test silenced the controller with five joint states
//! stamped 100 s ahead, then drove a joint past its limit with commands of its own. So a node pins the
//! first writer it hears while no other writer is matched on the topic, refuses and counts every other
//! writer's samples, and while two or more writers are matched and none is pinned, refuses them all
//! (which one is the real one cannot be told). The driver's pin lasts one KRC session; the controller's
//! its process's life.
//!
//! This keeps out a stray tool, a forgotten node or a careless peer. It is no authentication: DDS without
//! DDS-Security lets anyone on the network forge RTPS packets with the pinned writer's GUID (docs/safety.md: the separate layout trusts its DDS domain; the composed default takes no torque and no joint
//! state from the network).

/// A writer's identity: its DDS GUID (prefix and entity id), as `MessageInfo::publisher_gid` gives it.
pub type WriterId = [u8; 16];

/// Why a sample was not taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum WriterRefused {
    #[error("from a writer other than the pinned one")]
    Stranger,
    #[error("{0} writers publish and none is pinned: which one is real cannot be told")]
    Ambiguous(usize),
}

#[derive(Debug, Clone, Default)]
pub struct WriterPin {
    pinned: Option<WriterId>,
    /// Samples refused: from a stranger, or while the writers were ambiguous.
    pub refused: u64,
}

impl WriterPin {
    /// Takes a sample of `writer` or refuses it; `writers_matched` (asked only while none is pinned) is how
    /// many writers the middleware has matched on the topic. A sample arriving before discovery counted its
    /// writer reads 0: the sole writer, too.
    pub fn admit(&mut self, writer: WriterId, writers_matched: impl FnOnce() -> usize) -> Result<(), WriterRefused> {
        let verdict = match self.pinned {
            Some(w) if w == writer => Ok(()),
            Some(_) => Err(WriterRefused::Stranger),
            None => match writers_matched() {
                0 | 1 => {
                    self.pinned = Some(writer);
                    Ok(())
                }
                n => Err(WriterRefused::Ambiguous(n)),
            },
        };
        self.refused += u64::from(verdict.is_err());
        verdict
    }

    /// Forget the writer (a new KRC session): the next sole writer is pinned.
    pub fn release(&mut self) {
        self.pinned = None;
    }

    pub fn pinned(&self) -> Option<WriterId> {
        self.pinned
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sole_writer_is_pinned_and_every_other_refused_until_released() {
        let (a, b) = ([1; 16], [2; 16]);
        let mut pin = WriterPin::default();
        assert_eq!(pin.admit(a, || 1), Ok(()));
        assert_eq!(pin.pinned(), Some(a));
        // Pinned: the count is not asked, and a stranger is refused whatever it says.
        assert_eq!(pin.admit(b, || unreachable!()), Err(WriterRefused::Stranger));
        assert_eq!(pin.admit(a, || unreachable!()), Ok(()));
        assert_eq!(pin.refused, 1);
        pin.release();
        assert_eq!(pin.admit(b, || 0), Ok(()), "a sample before discovery counted its writer");
        assert_eq!(pin.admit(a, || 2), Err(WriterRefused::Stranger));
    }

    #[test]
    fn two_writers_and_none_pinned_are_both_refused() {
        let mut pin = WriterPin::default();
        assert_eq!(pin.admit([1; 16], || 2), Err(WriterRefused::Ambiguous(2)));
        assert_eq!(pin.admit([2; 16], || 3), Err(WriterRefused::Ambiguous(3)));
        assert_eq!((pin.pinned(), pin.refused), (None, 2));
        // One of them left: the other is the sole writer.
        assert_eq!(pin.admit([2; 16], || 1), Ok(()));
    }
}

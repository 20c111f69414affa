//! What the driver counts, published on /diagnostics.

/// What the driver counted (published on /diagnostics).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DriverCounters {
    pub measurements: u64,
    /// Measurements the sequence counter says never arrived.
    pub lost: u64,
    /// Repeated or reordered measurements (answered, not used for control).
    pub out_of_order: u64,
    pub malformed: u64,
    /// Well-formed measurements refused as physically implausible (unanswered).
    pub implausible: u64,
    /// Datagrams from anyone but the pinned KRC (unanswered).
    pub strangers: u64,
    /// KRC sessions begun (the first included).
    pub sessions: u64,
    /// Socket errors on receive or on sending a reply (counted; the driver goes on).
    pub network_errors: u64,
    /// Cycles answered with a command older than the watchdog, or none.
    pub stale_cycles: u64,
    /// Cycles held for a fault: a joint too fast, or heading into its position limit.
    pub overspeed_cycles: u64,
    pub limit_cycles: u64,
    pub commands_refused: u64,
    /// Commands refused for their age or their session (part of `commands_refused`).
    pub commands_too_old: u64,
    /// Commands from another writer than the pinned one, or while writers were ambiguous (not part of
    /// `commands_refused`: they never touch the present command).
    pub commands_from_strangers: u64,
    /// Latched faults cleared by the operator restarting the KRL program.
    pub faults_cleared: u64,
    /// Cycles the KRC commanded (any strategy) and the driver applied no torque for a reason other
    /// than a fault or a stale command: what /diagnostics names.
    pub waiting_cycles: u64,
}

impl DriverCounters {
    /// Datagrams refused since `before`, beside those accepted: what /diagnostics says about who talks
    /// FRI. Every datagram refused (a KRC sending nonsense, a stranger in the robot network) leaves the
    /// arm to the KRC's own fallback, and says so.
    pub fn refusals_since(&self, before: &DriverCounters) -> Refusals {
        Refusals {
            accepted: self.measurements.saturating_sub(before.measurements),
            implausible: self.implausible.saturating_sub(before.implausible),
            malformed: self.malformed.saturating_sub(before.malformed),
            strangers: self.strangers.saturating_sub(before.strangers),
        }
    }
}

/// Datagrams accepted and refused over an interval.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Refusals {
    pub accepted: u64,
    pub implausible: u64,
    pub malformed: u64,
    pub strangers: u64,
}

impl Refusals {
    pub fn refused(&self) -> u64 {
        self.implausible + self.malformed + self.strangers
    }

    /// Datagrams came, and not one was accepted.
    pub fn all_refused(&self) -> bool {
        self.refused() > 0 && self.accepted == 0
    }
}

impl std::fmt::Display for Refusals {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} FRI datagrams refused ({} implausible, {} malformed, {} from strangers), {} accepted",
            self.refused(),
            self.implausible,
            self.malformed,
            self.strangers,
            self.accepted
        )
    }
}

//! The event log every device keeps: each command it was sent, each edge it emitted or received,
//! and each fault it suffered, stamped with the (virtual or wall) time in nanoseconds. Tests read
//! it to check the order of operations (nothing sent before the plan was checked, the pattern
//! shown during each labelled exposure); recordings keep it beside the frames.

use serde::Serialize;

/// What kind of entry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Kind {
    /// A command the controller sent (`TriggerMode=On`, `AlpProjStartCont 2`).
    Command,
    /// A question that changes nothing (status, inquiry).
    Inquiry,
    /// A hardware edge: index pulse, trigger in, synch out, exposure start/end.
    Edge,
    /// A fault the device suffered (the simulated devices inject them).
    Fault,
}

/// One entry.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Event {
    pub t_ns: u64,
    pub device: &'static str,
    pub kind: Kind,
    pub what: String,
}

/// An append-only log.
#[derive(Clone, Debug, Default)]
pub struct EventLog {
    entries: Vec<Event>,
}

impl EventLog {
    pub fn push(&mut self, t_ns: u64, device: &'static str, kind: Kind, what: impl Into<String>) {
        self.entries.push(Event {
            t_ns,
            device,
            kind,
            what: what.into(),
        });
    }

    pub fn entries(&self) -> &[Event] {
        &self.entries
    }
}

//! The trigger chain of a run as its devices logged it (`trigger-chain.png` beside the
//! recording): wheel index pulses, the DMD's sequence starts and synch out, the camera's
//! exposures and deliveries, around the last frame's exposure and zoomed on its start.

use crate::error::Result;
use crate::log::{Event, Kind};
use specmux_report::timeline::{trigger_chain_png, Lane};
use std::path::Path;

/// Write the figure to `path`; a run that exposed no frame has no chain to draw (false).
pub fn write(path: &Path, events: &[Event]) -> Result<bool> {
    let mut edges: Vec<&Event> = events.iter().filter(|e| e.kind == Kind::Edge).collect();
    edges.sort_by_key(|e| e.t_ns);
    let Some((start, end)) = last_exposure(&edges) else {
        return Ok(false);
    };
    let lane = |name: &str, device: &str, what: &str| Lane {
        name: name.into(),
        edges: times(&edges, device, what),
        spans: vec![],
    };
    let index = times(&edges, "wheel", "index pulse");
    let turn = index
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(f64::INFINITY, f64::min);
    let turn = if turn.is_finite() { turn } else { 1e-3 };
    let lanes = vec![
        lane("wheel index pulse", "wheel", "index pulse"),
        lane("DMD sequence start (trigger in)", "dmd", "sequence"),
        lane("DMD synch out", "dmd", "synch out"),
        Lane {
            name: "camera exposure".into(),
            edges: vec![],
            spans: exposures(&edges),
        },
        lane("camera frame delivered", "camera", "delivered"),
    ];
    let margin = 0.1 * (end - start);
    let windows = vec![
        (
            "the last frame's exposure".to_string(),
            start - margin,
            end + margin,
        ),
        (
            "its start: three wheel turns".to_string(),
            start - 0.5 * turn,
            start + 2.5 * turn,
        ),
    ];
    trigger_chain_png(path, &lanes, &windows)?;
    Ok(true)
}

/// Times (s) of `device`'s edges whose text contains `what`.
fn times(edges: &[&Event], device: &str, what: &str) -> Vec<f64> {
    edges
        .iter()
        .filter(|e| e.device == device && e.what.contains(what))
        .map(|e| e.t_ns as f64 * 1e-9)
        .collect()
}

/// (start, end) of each exposure: a start edge and the next end edge.
fn exposures(edges: &[&Event]) -> Vec<(f64, f64)> {
    let starts = times(edges, "camera", "exposure start");
    let ends = times(edges, "camera", "exposure end");
    starts
        .iter()
        .filter_map(|&s| ends.iter().find(|&&e| e >= s).map(|&e| (s, e)))
        .collect()
}

/// The last complete exposure of the run.
fn last_exposure(edges: &[&Event]) -> Option<(f64, f64)> {
    exposures(edges).last().copied()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn edge(t_ns: u64, device: &'static str, what: &str) -> Event {
        Event {
            t_ns,
            device,
            kind: Kind::Edge,
            what: what.into(),
        }
    }

    #[test]
    fn exposures_pair_each_start_with_the_next_end() {
        let ev = [
            edge(5, "camera", "exposure start, frame 1"),
            edge(9, "camera", "exposure end, frame 1"),
            edge(12, "camera", "exposure start, frame 2"),
            edge(20, "camera", "exposure end, frame 2"),
            edge(21, "wheel", "index pulse 7"),
        ];
        let refs: Vec<&Event> = ev.iter().collect();
        let s = |ns: u64| ns as f64 * 1e-9;
        assert_eq!(exposures(&refs), vec![(s(5), s(9)), (s(12), s(20))]);
        assert_eq!(last_exposure(&refs), Some((s(12), s(20))));
        assert_eq!(times(&refs, "wheel", "index pulse"), vec![s(21)]);
        let none: Vec<&Event> = ev[4..].iter().collect();
        assert_eq!(last_exposure(&none), None);
    }
}

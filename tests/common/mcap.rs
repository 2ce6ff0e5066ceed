//! Trajectory logs compared message for message: a continued log (`sdem resume --mcap`)
//! against the uninterrupted run's.

use sdem::output::mcap::{Trajectory, scan_log};
use std::path::Path;

/// Every message of a log as written: (topic, sequence, log time, publish time, payload).
pub type Raw = Vec<(String, u32, u64, u64, Vec<u8>)>;

/// The messages of a finished log, in file order.
pub fn raw_messages(path: &Path) -> Raw {
    let mut out = Vec::new();
    let scan = scan_log(path, |h, d| {
        out.push((
            h.channel_id,
            h.sequence,
            h.log_time,
            h.publish_time,
            d.to_vec(),
        ));
        Ok(true)
    })
    .unwrap();
    assert!(scan.finished, "{}: not finished", path.display());
    assert!(scan.stopped.is_none(), "{:?}", scan.stopped);
    out.into_iter()
        .map(|(c, s, t, p, d)| (scan.channels[&c].topic.clone(), s, t, p, d))
        .collect()
}

/// The two logs hold the same frames (at least `min_frames`), rows, channels, scenario and
/// metadata, message for message, and `other`'s frames have distinct log times.
pub fn assert_same_log(reference: &Path, other: &Path, min_frames: usize) {
    let a = Trajectory::open(reference).unwrap();
    let b = Trajectory::open(other).unwrap();
    assert_eq!(a.frame_count(), b.frame_count(), "frame count");
    assert!(a.frame_count() >= min_frames, "{} frames", a.frame_count());
    let times = b.frame_log_times();
    assert!(
        times.windows(2).all(|w| w[0] < w[1]),
        "duplicate or unordered log times"
    );
    assert_eq!(a.frame_log_times(), times);
    for k in 0..a.frame_count() as i64 {
        let (x, y) = (a.frame(k).unwrap(), b.frame(k).unwrap());
        assert_eq!(x, y, "frame {k}");
        // Bit for bit: the Debug form prints every f64 in shortest round-trip form.
        assert_eq!(format!("{x:?}"), format!("{y:?}"), "frame {k}");
    }
    let (ra, rb) = (a.macro_rows().unwrap(), b.macro_rows().unwrap());
    assert_eq!(ra.len(), a.frame_count());
    assert_eq!(format!("{ra:?}"), format!("{rb:?}"), "macro rows");
    assert_eq!(a.channels(), b.channels());
    assert_eq!(a.metadata(), b.metadata());
    assert_eq!(a.summary_info("status"), Some("complete"));
    assert_eq!(a.scenario_text().unwrap(), b.scenario_text().unwrap());
    assert_eq!(a.library(), b.library());
    let (ma, mb) = (raw_messages(reference), raw_messages(other));
    assert_eq!(ma.len(), mb.len(), "message count");
    for (k, (x, y)) in ma.iter().zip(&mb).enumerate() {
        assert!(
            x == y,
            "message {k} differs: {:?} vs {:?}",
            (&x.0, x.1, x.2),
            (&y.0, y.1, y.2)
        );
    }
}

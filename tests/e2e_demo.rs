//! `dflat demo` in process: the whole sequence a user sees — hover in
//! position mode with the daemon in standby, the pilot engages, the path, a
//! pilot override and the hand-back — and the picture that shows it.

use dflat::demo::{self, DemoOptions};

#[path = "support/mod.rs"]
mod common;
use common::{LeastLate, STARVED_ATTEMPTS};

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_demo_flies_engagement_override_and_hand_back() {
    // A machine that starves the daemon past the pose timeout sends it,
    // rightly, to its failsafe and back (one engagement more): flown again
    // then, judged by the daemon's own tick lateness.
    let mut flights = LeastLate::new("demo");
    let dir = |attempt: usize| {
        std::env::temp_dir().join(format!("dflat-e2e-demo-{}-{attempt}", std::process::id()))
    };
    let mut flown = 0;
    for attempt in 1..=STARVED_ATTEMPTS {
        flown = attempt;
        let outcome = demo::run(&DemoOptions {
            speed: 5.0,
            out: dir(attempt),
            seconds: None,
        })
        .await
        .unwrap();
        let late = outcome.daemon.jitter_us.max as f64;
        if flights.offer(attempt, late, outcome) {
            break;
        }
    }
    let (judged, outcome) = flights.judged();
    for other in (1..=flown).filter(|a| *a != judged) {
        let _ = std::fs::remove_dir_all(dir(other));
    }
    let out = dir(judged);
    let text = outcome.summary_text();
    eprintln!("{text}");
    assert_eq!(outcome.failure(), None, "{text}");
    let steps: Vec<&str> = outcome.pilot.iter().map(|(_, what)| *what).collect();
    assert_eq!(
        steps,
        [
            "hover in POSCTL, daemon streaming",
            "engage (OFFBOARD)",
            "override (POSCTL)",
            "hand-back (OFFBOARD)"
        ],
        "{text}"
    );
    let d = &outcome.daemon;
    assert_eq!((d.engagements, d.disengagements), (2, 1), "{text}");
    assert!(d.time_in_state_s.standby > 1.0, "{text}");
    let step = outcome
        .handback_step_deg
        .expect("commands after the hand-back");
    assert!(step <= 5.0, "hand-back step {step:.1}°/tick");
    let e = outcome.path_error.as_ref().unwrap();
    // Measured (2026-11-25): median 0.001 m, p95 0.19 m, max 0.40 m.
    assert!(e.median < 0.05 && e.p95 < 0.5 && e.max < 1.0, "{text}");
    assert!(text.contains("2 engagements, 1 disengagements"), "{text}");
    // The picture: the daemon's stretches and the pilot's, each in the
    // legend once.
    let svg = std::fs::read_to_string(&outcome.plot[0]).unwrap();
    assert_eq!(svg.matches("daemon (true position)").count(), 1);
    assert_eq!(svg.matches("pilot, position mode").count(), 1);
    let _ = std::fs::remove_dir_all(&out);
}

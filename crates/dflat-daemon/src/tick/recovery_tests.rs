//! A controller that fails now and then, in the pure step: the failsafe
//! machine's recovery ([`super::failsafe::RECOVERY_S`]) says a streak once.

use super::tests::{Script, core, fly};
use super::*;

/// A controller that fails three ticks in five for 2 s: the fallback
/// (the held command) flies each failed tick, the controller's own
/// command each good one, and the streak is said once — not at every
/// failure after a good tick (20 STATUSTEXTs a second) — and its end once,
/// after `RECOVERY_S` of good ticks.
#[test]
fn an_intermittently_failing_controller_is_said_once() {
    let mut script = vec![Script::Command(0.05, 0.0); 10];
    for _ in 0..20 {
        script.extend([
            Script::Fail,
            Script::Command(0.04, 0.0),
            Script::Fail,
            Script::Fail,
            Script::Command(0.05, 0.0),
        ]);
    }
    script.push(Script::Command(0.03, 0.0));
    let (mut core, _) = core(script);
    let out = fly(&mut core, 200);
    assert!(
        out.iter().all(|o| o.command.is_some()),
        "a command every tick"
    );
    let texts: Vec<(usize, String)> = out
        .iter()
        .enumerate()
        .flat_map(|(k, o)| {
            o.texts.iter().filter_map(move |m| match m {
                MavMessage::STATUSTEXT(d) => Some((k, d.text.to_str().unwrap_or("").to_owned())),
                _ => None,
            })
        })
        .collect();
    let said = |what: &str| -> Vec<usize> {
        texts
            .iter()
            .filter(|(_, t)| t.contains(what))
            .map(|(k, _)| *k)
            .collect()
    };
    assert_eq!(said("control failed"), vec![10], "{texts:?}");
    // The last failure is at tick 108; the recovery is said a second of
    // good ticks later.
    let recovered = said("controller recovered (60 failed ticks)");
    assert_eq!(recovered, vec![108 + 50], "{texts:?}");
    let guards = core.counts().guards;
    assert_eq!((guards.held, guards.control_failsafes), (60, 0));
}

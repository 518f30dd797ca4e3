//! Hostile and random input, as property tests (the fuzzing CI can run on
//! every commit): nothing a file or the network can contain makes the core
//! panic, every file error has a location inside the file, and the wire
//! format round-trips.

use bite_core::graph::{Config, load_str};
use bite_core::ids::{BehaviorId, RobotId, TeamId};
use bite_core::interaction::Registry;
use bite_core::kernel::Kernel;
use bite_core::mission::Mission;
use bite_core::msg::{Body, Envelope, InstanceKey, Kind, decode, encode};
use bite_core::time::Time;
use proptest::prelude::*;
use std::sync::Arc;

const FORMATION: &str = include_str!("../../../examples/formation.yaml");

/// Every diagnostic points inside the text (or at no place at all).
fn located_inside(text: &str, d: &bite_core::diag::Diagnostics) -> Result<(), TestCaseError> {
    let lines = bite_core::yaml::lines(text).count().max(1) as u32 + 1;
    for x in &d.0 {
        prop_assert!(
            x.loc.line <= lines,
            "line {} beyond {} lines: {x}",
            x.loc.line,
            lines
        );
        prop_assert!(!x.message.is_empty());
    }
    Ok(())
}

/// Fragments that make YAML-shaped noise.
fn token() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("\n".to_string()),
        Just("  ".to_string()),
        Just(": ".to_string()),
        Just("- ".to_string()),
        Just("[".to_string()),
        Just("]".to_string()),
        Just("{".to_string()),
        Just("}".to_string()),
        Just(", ".to_string()),
        Just("&a ".to_string()),
        Just("*a".to_string()),
        Just("behaviors:".to_string()),
        Just("children".to_string()),
        Just("next".to_string()),
        Just("start: a".to_string()),
        Just("team: true".to_string()),
        Just("until: x >= 3 &&".to_string()),
        Just("pre: 'not y'".to_string()),
        Just("sync: sync.vote".to_string()),
        Just("members: \"2..\"".to_string()),
        "[a-d]{1,3}".prop_map(|s| s),
        any::<char>().prop_map(|c| c.to_string()),
    ]
}

fn cases() -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|c| c.parse().ok())
        .unwrap_or(512)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases(), failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn graph_loader_survives_random_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let text = String::from_utf8_lossy(&bytes).into_owned();
        if let Err(d) = load_str(&Arc::from("fuzz.yaml"), &text) {
            located_inside(&text, &d)?;
        }
    }

    #[test]
    fn graph_loader_survives_token_soup(tokens in proptest::collection::vec(token(), 0..60)) {
        let text = tokens.concat();
        if let Err(d) = load_str(&Arc::from("fuzz.yaml"), &text) {
            located_inside(&text, &d)?;
        }
    }

    #[test]
    fn graph_loader_survives_mutations_of_a_real_graph(
        edits in proptest::collection::vec((0usize..FORMATION.len(), 0usize..8, token()), 1..6)
    ) {
        let mut text = FORMATION.to_string();
        for (at, cut, insert) in edits {
            let at = at.min(text.len());
            let at = (0..=at).rev().find(|i| text.is_char_boundary(*i)).unwrap_or(0);
            let end = (at + cut).min(text.len());
            let end = (end..=text.len()).find(|i| text.is_char_boundary(*i)).unwrap_or(text.len());
            text.replace_range(at..end, &insert);
        }
        match load_str(&Arc::from("fuzz.yaml"), &text) {
            Err(d) => located_inside(&text, &d)?,
            // A mutation that still loads must still resolve or fail cleanly.
            Ok(g) => {
                let _ = Mission::new(g, &Registry::core());
            }
        }
    }

    #[test]
    fn config_loader_survives_token_soup(tokens in proptest::collection::vec(token(), 0..40)) {
        let text = format!("bindings:\n  {}", tokens.concat());
        if let Err(d) = Config::load_str(&Arc::from("fuzz.yaml"), &text) {
            located_inside(&text, &d)?;
        }
    }

    #[test]
    fn wire_decoding_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
        let _ = decode(&bytes);
    }

    #[test]
    fn wire_format_round_trips(env in envelope()) {
        let bytes = encode(&env);
        prop_assert_eq!(decode(&bytes), Ok(env.clone()));
        // Any truncation is an error, never a different message.
        for cut in 0..bytes.len() {
            prop_assert!(decode(&bytes[..cut]).is_err());
        }
    }

    /// A kernel fed arbitrary (even forged) messages between ticks never
    /// panics and keeps its organization sound.
    #[test]
    fn kernel_survives_arbitrary_messages(msgs in proptest::collection::vec(envelope(), 0..80)) {
        let g = load_str(&Arc::from("formation.yaml"), FORMATION).map_err(|d| TestCaseError::fail(d.to_string()))?;
        let cfg = Config::load_str(&Arc::from("c.yaml"), "defaults: { terminate: term.local }\nbindings: { formation.terminate: term.local }")
            .map_err(|d| TestCaseError::fail(d.to_string()))?;
        let g = g.with_config(&cfg).map_err(|d| TestCaseError::fail(d.to_string()))?;
        let m = Arc::new(Mission::new(g, &Registry::core()).map_err(|d| TestCaseError::fail(d.to_string()))?);
        let mut k = Kernel::new(m, RobotId(1), 7);
        k.tick(Time::ZERO, &[]);
        for (i, env) in msgs.into_iter().enumerate() {
            let t = Time::from_millis(10 * i as u64 + 5);
            k.message(t, env);
            k.tick(t, &[]);
            while k.poll_output().is_some() {}
        }
        prop_assert!(k.org().check_invariants().is_ok(), "{:?}", k.org().check_invariants());
    }
}

fn envelope() -> impl Strategy<Value = Envelope> {
    let key = (
        prop_oneof![Just(TeamId::ROOT), any::<u64>().prop_map(TeamId)],
        0u32..14,
        prop_oneof![
            Just(Kind::Sync),
            Just(Kind::Allocate),
            Just(Kind::Terminate)
        ],
        0u32..4,
    )
        .prop_map(|(team, b, kind, epoch)| InstanceKey {
            team,
            behavior: BehaviorId(b),
            kind,
            epoch,
            round: epoch % 3,
        });
    let ids = proptest::collection::vec((0u32..14).prop_map(BehaviorId), 0..4);
    let body = prop_oneof![
        ids.clone()
            .prop_map(|candidates| Body::Propose { candidates }),
        proptest::option::of((0u32..14).prop_map(BehaviorId))
            .prop_map(|choice| Body::Vote { choice }),
        ids.clone().prop_map(|ranking| Body::Ballot { ranking }),
        proptest::option::of((0u32..14).prop_map(BehaviorId))
            .prop_map(|choice| Body::Decision { choice }),
        Just(Body::Done),
        Just(Body::Ack),
        Just(Body::Query),
        proptest::option::of((0u32..14).prop_map(BehaviorId))
            .prop_map(|next| Body::Release { next }),
        (
            proptest::option::of((0u32..14).prop_map(BehaviorId)),
            any::<f64>()
        )
            .prop_map(|(about, value)| Body::Value { about, value }),
        ("[a-z]{0,6}", "[a-z]{0,6}").prop_map(|(name, value)| Body::Attribute { name, value }),
        (any::<u16>(), proptest::collection::vec(any::<u8>(), 0..16))
            .prop_map(|(tag, data)| Body::Custom { tag, data }),
        (
            proptest::collection::vec((0u32..14).prop_map(BehaviorId), 0..3),
            proptest::collection::vec(((0u32..6).prop_map(RobotId), 0u32..4), 0..5)
        )
            .prop_map(|(children, members)| Body::Assignment { children, members }),
        (
            proptest::collection::vec((0u32..14).prop_map(BehaviorId), 0..4),
            any::<u32>(),
            proptest::option::of((0u32..5).prop_map(RobotId))
        )
            .prop_map(|(items, round, winner)| Body::Call {
                items,
                round,
                winner
            }),
        ((0u32..14).prop_map(BehaviorId), any::<f64>(), any::<u32>())
            .prop_map(|(item, value, round)| Body::Bid { item, value, round }),
        proptest::collection::vec(((0u32..14).prop_map(BehaviorId), any::<f64>()), 0..5)
            .prop_map(|values| Body::Costs { values }),
        (
            any::<u32>(),
            (0u32..14).prop_map(BehaviorId),
            any::<u32>(),
            any::<f64>()
        )
            .prop_map(|(slot, item, hops, threshold)| Body::Token {
                slot,
                item,
                hops,
                threshold
            }),
        any::<u32>().prop_map(|slot| Body::Claim { slot }),
        proptest::collection::vec((0u32..6).prop_map(RobotId), 0..3)
            .prop_map(|lost| Body::Reallocate { lost }),
        (
            proptest::option::of((0u32..14).prop_map(BehaviorId)),
            ids.clone(),
            proptest::collection::vec(((0u32..6).prop_map(RobotId), 0u32..4), 0..4)
        )
            .prop_map(|(choice, children, members)| Body::Missed {
                choice,
                children,
                members
            }),
    ];
    (key, (0u32..5).prop_map(RobotId), 0u64..50, body).prop_map(|(instance, sender, seq, body)| {
        Envelope {
            instance,
            sender,
            seq,
            body,
        }
    })
}

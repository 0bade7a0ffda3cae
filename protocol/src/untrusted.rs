//! What a hub sends is checked before it is used: a hub may be old, broken or lying, and the
//! client must come out of it with a [`HubError`] that names the hub — never a panic, an
//! out-of-bounds write, or an error kind that means something else here (`Interrupted` is
//! raised as Python's `KeyboardInterrupt`).

use crate::{HubError, OpenReply};
use envhub_shm::{BatchLayout, Layout};

/// An error a hub sent, as the client may take it: the kinds that describe the caller's
/// request or the hub's envs pass as they are (`Refused` naming the hub that sent it); any
/// other kind (`Interrupted`, `HubLost`, `Daemon`, shared-memory errors, ...) describes this
/// process, not the hub, and becomes text that names the hub.
pub fn from_hub(hub: &str, e: HubError) -> HubError {
    match e {
        e if describes_the_request(&e) => e,
        HubError::Refused { reason, hint, .. } => HubError::Refused {
            hub: hub.to_string(),
            reason,
            hint,
        },
        HubError::Remote(text) => HubError::Remote(format!("hub `{hub}`: {text}")),
        other => HubError::Remote(format!("hub `{hub}` reported: {other}")),
    }
}

/// Whether an error another process sent describes the caller's request or that process's
/// envs (an unknown id, a bad config, an unavailable adapter, ...), and so may be raised here
/// as it came. The daemon's and a hub's checks both start from these kinds.
pub fn describes_the_request(e: &HubError) -> bool {
    matches!(
        e,
        HubError::Registry(_)
            | HubError::NoAdapter { .. }
            | HubError::Unavailable { .. }
            | HubError::InvalidConfig { .. }
            | HubError::MakeFailed(_)
            | HubError::InvalidAction { .. }
            | HubError::InvalidState(_)
    )
}

/// A reply that breaks the protocol: the hub named, what was wrong.
pub fn lying(hub: &str, what: impl std::fmt::Display) -> HubError {
    HubError::Remote(format!(
        "hub `{hub}` sent {what}\nhint: the hub runs another envhub version or misbehaves; leave it out of the placement"
    ))
}

/// The byte layouts of a remote slice of `num_envs` envs, from an open reply whose spaces are
/// checked first (sizes with checked arithmetic, within the limits of
/// [`envhub_core::Space::check`]).
pub fn check_open_reply(
    hub: &str,
    reply: &OpenReply,
    num_envs: usize,
    with_final_obs: bool,
) -> Result<(Layout, BatchLayout), HubError> {
    let spec = &reply.spec;
    let obs = spec.observation_space.check().map_err(|e| {
        lying(
            hub,
            format_args!("an observation space that is unusable: {e}"),
        )
    })?;
    let act = spec
        .action_space
        .check()
        .map_err(|e| lying(hub, format_args!("an action space that is unusable: {e}")))?;
    if reply.session.is_empty()
        || reply.session.len() > 200
        || !reply
            .session
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
    {
        return Err(lying(
            hub,
            format_args!(
                "a session id `{}` that is not 1 to 200 letters, digits, `-` or `_`",
                reply.session.escape_debug()
            ),
        ));
    }
    let requests = Layout::checked(num_envs, act);
    let rows = BatchLayout::checked(num_envs, obs, with_final_obs);
    match (requests, rows) {
        (Some(requests), Some(rows)) => Ok((requests, rows)),
        _ => Err(lying(
            hub,
            format_args!(
                "spaces whose batch of {num_envs} envs ({obs} bytes per observation, {act} per action) does not fit in memory"
            ),
        )),
    }
}

/// One env that failed, as a worker reports it (`status::ENV_FAILED`).
#[derive(Debug, serde::Deserialize)]
pub struct FailedEnvs {
    /// `(env index within the worker, message)`.
    pub failed: Vec<(usize, String)>,
    /// The infos of the envs that stepped (the worker's info section otherwise).
    pub info: Option<serde_json::Value>,
}

/// Reads the failure report of `who` (a worker, a hub), which was sent envs `sent` (session
/// indices; its envs start at `offset`): every env it names must be one of them.
pub fn read_failure_report(
    bytes: &[u8],
    who: &str,
    sent: &[usize],
    offset: usize,
) -> Result<FailedEnvs, String> {
    let report: FailedEnvs = serde_json::from_slice(bytes)
        .map_err(|e| format!("{who} sent an unreadable failure report: {e}"))?;
    if report.failed.len() > sent.len() {
        return Err(format!(
            "{who} reported {} failed envs; it was sent {}",
            report.failed.len(),
            sent.len()
        ));
    }
    match report
        .failed
        .iter()
        .find(|(k, _)| offset.checked_add(*k).is_none_or(|e| !sent.contains(&e)))
    {
        Some((k, _)) => Err(format!(
            "{who} reported env {k} of its own failed, which is not among the {} envs it was sent",
            sent.len()
        )),
        None => Ok(report),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn reply(observation_space: serde_json::Value, session: &str) -> OpenReply {
        serde_json::from_value(json!({
            "session": session,
            "spec": {
                "observation_space": observation_space,
                "action_space": {"type": "discrete", "n": 2, "start": 0},
                "max_episode_steps": null,
                "pid": 1,
            },
            "route": {"adapter": "classic_control", "env_id": "CartPole-v1", "config": {}},
            "workers": 1,
        }))
        .expect("an open reply")
    }

    #[test]
    fn an_error_kind_that_means_something_here_becomes_text_naming_the_hub() {
        for e in [
            HubError::Interrupted,
            HubError::HubLost {
                hub: "other".into(),
                envs: "0..4".into(),
                why: "made up".into(),
            },
            HubError::Daemon {
                socket: "/x".into(),
                reason: "y".into(),
            },
        ] {
            let kind = std::mem::discriminant(&e);
            let back = from_hub("box1", e);
            assert!(matches!(back, HubError::Remote(_)), "{back:?}");
            assert_ne!(std::mem::discriminant(&back), kind);
            assert!(back.to_string().contains("hub `box1`"), "{back}");
        }
        let refused = from_hub(
            "box1",
            HubError::Refused {
                hub: "someone-else".into(),
                reason: "r".into(),
                hint: "h".into(),
            },
        );
        assert!(matches!(&refused, HubError::Refused { hub, .. } if hub == "box1"));
        let invalid = from_hub("box1", HubError::InvalidState("reset first".into()));
        assert!(matches!(invalid, HubError::InvalidState(_)));
    }

    #[test]
    fn hostile_spaces_in_an_open_reply_are_refused_naming_the_hub() {
        let huge = usize::MAX / 2;
        let cases = [
            // A product of dimensions that overflows.
            json!({"type": "multi_binary", "shape": [huge, 4]}),
            // Within `usize`, far beyond any observation.
            json!({"type": "multi_binary", "shape": [1usize << 40]}),
            // Bounds that do not match the shape.
            json!({"type": "box", "dtype": "float32", "shape": [3], "low": [0.0], "high": [1.0]}),
            json!({"type": "discrete", "n": 0, "start": 0}),
            json!({"type": "multi_discrete", "nvec": [2, 3], "start": [0]}),
        ];
        for space in cases {
            let e = check_open_reply("box1", &reply(space.clone(), "s1-2"), 4, true)
                .expect_err("refused");
            assert!(e.to_string().contains("hub `box1`"), "{space}: {e}");
        }
        // Fine spaces, too many envs for memory.
        let ok = json!({"type": "multi_binary", "shape": [1 << 20]});
        let e = check_open_reply("box1", &reply(ok.clone(), "s1-2"), usize::MAX / 8, true)
            .expect_err("refused");
        assert!(e.to_string().contains("does not fit"), "{e}");
        let (req, rows) = check_open_reply("box1", &reply(ok.clone(), "s1-2"), 4, true).unwrap();
        assert_eq!((req.num_envs, rows.obs_bytes), (4, 1 << 20));
        // A session id that would change the key it is used in.
        for bad in ["", "a/b", "*", "s1/../x", "x?y"] {
            let e =
                check_open_reply("box1", &reply(ok.clone(), bad), 4, false).expect_err("refused");
            assert!(e.to_string().contains("session id"), "{bad}: {e}");
        }
    }
}

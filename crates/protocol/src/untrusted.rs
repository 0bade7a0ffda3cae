//! What a hub sends is checked before it is used: a hub may be old, broken or lying, and the
//! client must come out of it with a [`HubError`] that names the hub — never a panic, an
//! out-of-bounds write, or an error kind that means something else here (`Interrupted` is
//! raised as Python's `KeyboardInterrupt`).

use crate::{HubError, OpenReply};
use envhub_shm::{BatchLayout, Layout, ReadySpec};

/// Checks the spaces a worker (user code) announced, as [`check_open_reply`] does a hub's:
/// every size with checked arithmetic and within [`Space::check`]'s limits, neither space
/// empty (a value of no bytes), and a batch of `num_envs` that fits in memory. Returns the
/// request layout, or what is wrong.
///
/// [`Space::check`]: envhub_core::Space::check
pub fn check_worker_spaces(spec: &ReadySpec, num_envs: usize) -> Result<Layout, String> {
    let obs = spec
        .observation_space
        .check()
        .map_err(|e| format!("an observation space that is unusable: {e}"))?;
    let act = spec
        .action_space
        .check()
        .map_err(|e| format!("an action space that is unusable: {e}"))?;
    if obs == 0 || act == 0 {
        return Err(format!(
            "spaces of which one takes no bytes (observation {obs}, action {act}): {} / {}",
            spec.observation_space, spec.action_space
        ));
    }
    match (
        Layout::checked(num_envs, act),
        BatchLayout::checked(num_envs, obs, true),
    ) {
        (Some(layout), Some(_)) => Ok(layout),
        _ => Err(format!(
            "spaces whose batch of {num_envs} envs ({obs} bytes per observation, {act} per action) does not fit in memory"
        )),
    }
}

/// Reads an open request a client sent (the request and its hello), bounded before it is decoded: its length (at most
/// [`MAX_OPEN_REQUEST_BYTES`]), then, in one pass over the bytes that allocates nothing, its
/// nesting ([`MAX_OPEN_REQUEST_DEPTH`]) and its number of values
/// ([`MAX_OPEN_REQUEST_VALUES`]); only then is it parsed, so what a parse can allocate is
/// bounded by a small multiple of those. Returns what was wrong otherwise.
///
/// [`MAX_OPEN_REQUEST_BYTES`]: crate::MAX_OPEN_REQUEST_BYTES
/// [`MAX_OPEN_REQUEST_DEPTH`]: crate::MAX_OPEN_REQUEST_DEPTH
/// [`MAX_OPEN_REQUEST_VALUES`]: crate::MAX_OPEN_REQUEST_VALUES
pub fn read_open_request(bytes: &[u8]) -> Result<crate::OpenMessage, String> {
    use crate::{MAX_OPEN_REQUEST_DEPTH, MAX_OPEN_REQUEST_VALUES};
    check_open_request_size(bytes.len())?;
    let (mut depth, mut values) = (0usize, 0usize);
    let (mut in_string, mut escaped) = (false, false);
    for &b in bytes {
        if in_string {
            match (escaped, b) {
                (true, _) => escaped = false,
                (false, b'\\') => escaped = true,
                (false, b'"') => in_string = false,
                _ => {}
            }
            continue;
        }
        match b {
            b'"' => in_string = true,
            b'[' | b'{' => {
                depth += 1;
                values += 1;
                if depth > MAX_OPEN_REQUEST_DEPTH {
                    return Err(format!(
                        "nested deeper than {MAX_OPEN_REQUEST_DEPTH} levels"
                    ));
                }
            }
            b']' | b'}' => depth = depth.saturating_sub(1),
            b',' => values += 1,
            _ => {}
        }
        if values > MAX_OPEN_REQUEST_VALUES {
            return Err(format!(
                "more than {MAX_OPEN_REQUEST_VALUES} values (remote kwargs hold at most {MAX_KWARG_VALUES})"
            ));
        }
    }
    serde_json::from_slice(bytes).map_err(|e| format!("unreadable: {e}"))
}

/// Refuses an open request of `len` bytes, more than [`crate::MAX_OPEN_REQUEST_BYTES`]:
/// checked before the bytes are copied or read.
pub fn check_open_request_size(len: usize) -> Result<(), String> {
    let max = crate::MAX_OPEN_REQUEST_BYTES;
    if len > max {
        return Err(format!(
            "{len} bytes, more than the {max} an open request may have (its kwargs are too large)"
        ));
    }
    Ok(())
}

/// The deepest nesting of a remote client's kwarg value.
const MAX_KWARG_DEPTH: usize = 16;
/// The most values (leaves and containers) in a remote client's kwargs.
const MAX_KWARG_VALUES: usize = 10_000;
/// The longest string in a remote client's kwargs.
const MAX_KWARG_STRING: usize = 1024;

/// Checks the kwargs a remote client asks a hub to pass to its env, against an allowlist:
/// numbers, booleans, `null`, strings that cannot name a file, and lists and maps of those
/// (bounded in depth, count and length). A string names a file when it holds a `/` or `\`,
/// starts with `~` or `.`, ends in an extension (`ant.xml`), or names an entry of the hub's
/// working folder, where its workers start (`passwd` in `/etc`) — anything an adapter could
/// open relative to its folder. Keys must be plain names. Returns the path of the first value
/// refused (`kwargs.robot[2].model`) and why.
pub fn check_remote_kwargs(
    kwargs: &std::collections::BTreeMap<String, serde_json::Value>,
) -> Result<(), String> {
    // No working folder to resolve against: every bare name is then refused.
    let here = std::env::current_dir().unwrap_or_default();
    check_remote_kwargs_in(kwargs, &here)
}

/// [`check_remote_kwargs`], with `folder` as the workers' working folder.
fn check_remote_kwargs_in(
    kwargs: &std::collections::BTreeMap<String, serde_json::Value>,
    folder: &std::path::Path,
) -> Result<(), String> {
    let mut count = 0;
    for (key, value) in kwargs {
        check_kwarg(&format!("kwargs.{key}"), key, value, 0, &mut count, folder)?;
    }
    Ok(())
}

fn check_kwarg(
    at: &str,
    key: &str,
    value: &serde_json::Value,
    depth: usize,
    count: &mut usize,
    folder: &std::path::Path,
) -> Result<(), String> {
    use serde_json::Value;
    *count += 1;
    if *count > MAX_KWARG_VALUES {
        return Err(format!("more than {MAX_KWARG_VALUES} values in all"));
    }
    if depth > MAX_KWARG_DEPTH {
        return Err(format!(
            "`{at}` is nested deeper than {MAX_KWARG_DEPTH} levels"
        ));
    }
    if key.is_empty()
        || key.len() > 128
        || !key
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-')
    {
        return Err(format!(
            "`{at}`: the key `{}` is not a plain name (letters, digits, `_`, `-`)",
            key.escape_debug()
        ));
    }
    match value {
        Value::Null | Value::Bool(_) | Value::Number(_) => Ok(()),
        Value::String(text) => {
            if text.len() > MAX_KWARG_STRING {
                return Err(format!(
                    "`{at}` is a string longer than {MAX_KWARG_STRING} bytes"
                ));
            }
            if names_a_file(text) {
                return Err(format!("`{at}` = {:?} may name a file on the hub", text));
            }
            if !text.is_empty()
                && (folder.as_os_str().is_empty() || folder.join(text).symlink_metadata().is_ok())
            {
                return Err(format!(
                    "`{at}` = {:?} names a file or folder where the hub's workers start",
                    text
                ));
            }
            Ok(())
        }
        Value::Array(items) => items.iter().enumerate().try_for_each(|(i, v)| {
            check_kwarg(&format!("{at}[{i}]"), key, v, depth + 1, count, folder)
        }),
        Value::Object(map) => map.iter().try_for_each(|(k, v)| {
            check_kwarg(&format!("{at}.{k}"), k, v, depth + 1, count, folder)
        }),
    }
}

/// Whether a string could name a file or folder: a separator, a home or relative start, or
/// a file extension (letters after the last dot; `1.5` and `v1.0` are not).
fn names_a_file(text: &str) -> bool {
    if text.contains(['/', '\\', '\0']) || text.starts_with(['~', '.']) {
        return true;
    }
    text.rsplit_once('.').is_some_and(|(stem, ext)| {
        !stem.is_empty()
            && (1..=8).contains(&ext.len())
            && ext.bytes().all(|b| b.is_ascii_alphanumeric())
            && ext.bytes().any(|b| b.is_ascii_alphabetic())
    })
}

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
            | HubError::Closed { .. }
            | HubError::NotReset { .. }
            | HubError::MustReset { .. }
            | HubError::SpacesDiffer(_)
            | HubError::Internal(_)
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
    if act == 0 || obs == 0 {
        return Err(lying(
            hub,
            format_args!("spaces of which one takes no bytes (observation {obs}, action {act})"),
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
            "hello": {"exchange": "ab".repeat(32), "identity": "cd".repeat(32), "proof": "ef".repeat(64)},
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
    fn open_requests_are_bounded_in_size_depth_and_values_before_they_are_parsed() {
        let hello = r#"{"exchange":"ab","identity":"cd","time_ms":1,"proof":"ef"}"#;
        let request = |kwargs: &str| {
            format!(
                r#"{{"request":{{"id":"gym-cartpole","config":{{"num_envs":1,"extra":{{"k":{kwargs}}}}},"client":"envhub/client/c","restart_on_crash":false,"step_timeout_ms":1000}},"hello":{hello}}}"#
            )
        };
        let ok = read_open_request(request("[1,2,{\"a\":\"]]]\\\"[[\"}]").as_bytes())
            .expect("a plain request (brackets inside strings do not count)");
        assert_eq!(ok.request.id, "gym-cartpole");
        // Too long: refused by its length alone, whatever it holds.
        let long = vec![b' '; crate::MAX_OPEN_REQUEST_BYTES + 1];
        let err = read_open_request(&long).unwrap_err();
        assert!(err.contains("bytes, more than"), "{err}");
        // Too deep: refused before serde's own recursion limit is reached.
        let deep = format!("{}{}", "[".repeat(40), "]".repeat(40));
        let err = read_open_request(request(&deep).as_bytes()).unwrap_err();
        assert!(err.contains("nested deeper"), "{err}");
        let fine = format!("{}{}", "[".repeat(20), "]".repeat(20));
        read_open_request(request(&fine).as_bytes()).expect("20 levels are fine");
        // Too many values, within the length.
        let many = format!("[{}0]", "0,".repeat(crate::MAX_OPEN_REQUEST_VALUES));
        assert!(many.len() < crate::MAX_OPEN_REQUEST_BYTES);
        let err = read_open_request(request(&many).as_bytes()).unwrap_err();
        assert!(err.contains("values"), "{err}");
        let err = read_open_request(b"{\"id\": 3}").unwrap_err();
        assert!(err.contains("unreadable"), "{err}");
    }

    #[test]
    fn remote_kwargs_pass_only_plain_values_that_name_no_file() {
        let kwargs =
            |v: serde_json::Value| -> std::collections::BTreeMap<String, serde_json::Value> {
                serde_json::from_value(v).unwrap()
            };
        let fine = kwargs(json!({
            "frame_skip": 5, "reset_noise_scale": 0.1, "render": false, "mode": "rgb_array",
            "version": "v1.0", "ratio": "1.5", "none": null,
            "nested": {"weights": [1, 2.5, {"name": "CartPole-v1"}]},
        }));
        assert_eq!(check_remote_kwargs(&fine), Ok(()));
        for (bad, needle) in [
            (json!({"xmlfile": "ant.xml"}), "kwargs.xmlfile"),
            (json!({"folder": "/etc"}), "kwargs.folder"),
            (
                json!({"robot": {"model": "../secret"}}),
                "kwargs.robot.model",
            ),
            (json!({"models": ["a", "b/c"]}), "kwargs.models[1]"),
            (json!({"home": "~root"}), "kwargs.home"),
            (json!({"win": "C:\\x"}), "kwargs.win"),
            (json!({"hidden": ".ssh"}), "kwargs.hidden"),
            (json!({"bad key": 1}), "not a plain name"),
            (json!({"long": "x".repeat(2000)}), "longer than"),
        ] {
            let e = check_remote_kwargs(&kwargs(bad.clone())).expect_err("refused");
            assert!(e.contains(needle), "{bad}: {e}");
        }
        let mut deep = json!(1);
        for _ in 0..40 {
            deep = json!([deep]);
        }
        let e = check_remote_kwargs(&kwargs(json!({"deep": deep}))).expect_err("too deep");
        assert!(e.contains("deeper"), "{e}");
        let many = json!({"many": vec![0; 20_000]});
        assert!(check_remote_kwargs(&kwargs(many)).is_err());
        // A bare name without an extension is refused where it names an entry of the
        // workers' folder (`passwd` for a hub started in `/etc`), and passes where it does not.
        let etc = std::env::temp_dir().join(format!("envhub-kwargs-{}", std::process::id()));
        std::fs::create_dir_all(&etc).unwrap();
        std::fs::write(etc.join("passwd"), "root:x:0:0").unwrap();
        let passwd = kwargs(json!({"model": "passwd", "mode": "rgb_array"}));
        let e = check_remote_kwargs_in(&passwd, &etc).expect_err("refused");
        assert!(e.contains("kwargs.model") && e.contains("passwd"), "{e}");
        let elsewhere = etc.join("empty");
        std::fs::create_dir_all(&elsewhere).unwrap();
        assert_eq!(check_remote_kwargs_in(&passwd, &elsewhere), Ok(()));
        assert_eq!(
            check_remote_kwargs_in(&kwargs(json!({"nested": [{"m": "passwd"}]})), &etc)
                .expect_err("refused nested"),
            "`kwargs.nested[0].m` = \"passwd\" names a file or folder where the hub's workers start"
        );
        std::fs::remove_dir_all(&etc).unwrap();
    }

    #[test]
    fn hostile_action_spaces_of_a_worker_are_refused_like_observation_spaces() {
        let spec = |action: serde_json::Value| -> ReadySpec {
            serde_json::from_value(json!({
                "observation_space": {"type": "box", "dtype": "float32", "shape": [4],
                    "low": [0.0, 0.0, 0.0, 0.0], "high": [1.0, 1.0, 1.0, 1.0]},
                "action_space": action,
                "max_episode_steps": null,
                "pid": 1,
            }))
            .expect("a ready spec")
        };
        let huge = usize::MAX / 2;
        for (action, needle) in [
            (
                json!({"type": "multi_binary", "shape": [huge, 4]}),
                "action space",
            ),
            (
                json!({"type": "multi_binary", "shape": [1usize << 40]}),
                "action space",
            ),
            (json!({"type": "multi_binary", "shape": [0]}), "no bytes"),
            (json!({"type": "dict", "spaces": []}), "no bytes"),
            (
                json!({"type": "discrete", "n": 0, "start": 0}),
                "action space",
            ),
            (
                json!({"type": "box", "dtype": "float32", "shape": [2], "low": [0.0], "high": [1.0]}),
                "action space",
            ),
        ] {
            let e = check_worker_spaces(&spec(action.clone()), 4).expect_err("refused");
            assert!(e.contains(needle), "{action}: {e}");
        }
        let fine = spec(json!({"type": "multi_binary", "shape": [1 << 20]}));
        assert_eq!(check_worker_spaces(&fine, 4).unwrap().act_bytes, 1 << 20);
        let e = check_worker_spaces(&fine, usize::MAX / 8).expect_err("too many envs");
        assert!(e.contains("does not fit"), "{e}");
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

//! The hub daemon's messages (`envhub serve`): one JSON object per line each way over its
//! Unix socket.
//!
//! - Request: `{"op": "ping" | "adapters" | "status" | "route" | "launch" | "exit_status",
//!   ...}` with the op's fields, and `user_adapters` on `adapters`, `route` and `launch` when
//!   the client has any (absent: none, as from a client that predates it).
//! - Reply: `{"ok": value}`, or `{"err": "text", "error": {...}}` (the [`HubError`] as it
//!   serializes beside its text; text only from an older daemon).
//!
//! Both ends read lines of another process, so lines are bounded ([`read_line_bounded`]) and
//! every field is checked here, before the hub acts on it.

use crate::HubError;
use envhub_core::EnvConfig;
use envhub_shm::WorkerJob;
use serde_json::{Value, json};
use std::path::PathBuf;
use std::time::Duration;

/// The longest line a daemon request or reply may be: a launch carries the job (a pickled
/// env function of a drop-in at most a few MiB), a reply the adapters' list.
pub const MAX_LINE: usize = 16 << 20;

/// Reads one line of at most `max` bytes (its newline included) into `line` (0 at the end of
/// the stream); a longer one is an error, and the stream cannot be read further.
pub fn read_line_bounded(
    reader: &mut impl std::io::BufRead,
    max: usize,
    line: &mut String,
) -> std::io::Result<usize> {
    use std::io::{BufRead, Read};
    line.clear();
    let n = reader.take(max as u64 + 1).read_line(line)?;
    if n > max {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("a line longer than {max} bytes"),
        ));
    }
    Ok(n)
}

/// User adapters beyond the daemon's own: import paths, and the `PYTHONPATH` entries their
/// modules need. A daemon gets them from each client with its requests, because the client's
/// environment never reaches the daemon's workers; empty (the default) means none.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct UserAdapters {
    /// Import paths, `module:Class`.
    pub adapters: Vec<String>,
    /// Absolute folders to put first on the worker's `PYTHONPATH`.
    pub pythonpath: Vec<PathBuf>,
}

impl UserAdapters {
    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.adapters.is_empty() && self.pythonpath.is_empty()
    }
}

/// How long a launch may take to start its worker when the request does not say.
pub const DEFAULT_START_TIMEOUT: Duration = Duration::from_secs(60);

/// A request to the daemon, checked.
#[derive(Clone, Debug)]
pub enum Request {
    /// Is it there.
    Ping,
    /// The adapters it can run (its own and `user`).
    Adapters {
        /// The client's user adapters.
        user: UserAdapters,
    },
    /// Workers it runs, over all clients.
    Status,
    /// Route a registry id.
    Route {
        /// Registry id.
        id: String,
        /// The caller's config.
        config: EnvConfig,
        /// The client's user adapters.
        user: UserAdapters,
    },
    /// Start a worker.
    Launch {
        /// Its job (boxed: the largest request by far).
        job: Box<WorkerJob>,
        /// How long it may take to report ready.
        start_timeout: Duration,
        /// The client's user adapters.
        user: UserAdapters,
    },
    /// How a worker it started has ended.
    ExitStatus {
        /// The worker's pid.
        pid: u32,
    },
}

fn invalid(reason: String) -> HubError {
    HubError::InvalidConfig {
        what: "daemon request",
        reason,
    }
}

impl Request {
    /// Its op's name.
    pub fn op(&self) -> &'static str {
        match self {
            Request::Ping => "ping",
            Request::Adapters { .. } => "adapters",
            Request::Status => "status",
            Request::Route { .. } => "route",
            Request::Launch { .. } => "launch",
            Request::ExitStatus { .. } => "exit_status",
        }
    }

    /// The line a client sends (without its newline).
    pub fn encode(&self) -> String {
        let mut v = json!({ "op": self.op() });
        let user = match self {
            Request::Adapters { user } => Some(user),
            Request::Route { id, config, user } => {
                v["id"] = json!(id);
                v["config"] = serde_json::to_value(config).expect("configs serialize");
                Some(user)
            }
            Request::Launch {
                job,
                start_timeout,
                user,
            } => {
                v["job"] = serde_json::to_value(job).expect("jobs serialize");
                v["start_timeout_ms"] =
                    json!(u64::try_from(start_timeout.as_millis()).unwrap_or(u64::MAX));
                Some(user)
            }
            Request::ExitStatus { pid } => {
                v["pid"] = json!(pid);
                None
            }
            Request::Ping | Request::Status => None,
        };
        // An older daemon ignores the field; it is sent only when there is something in it.
        if let Some(user) = user.filter(|u| !u.is_empty()) {
            v["user_adapters"] = serde_json::to_value(user).expect("paths serialize");
        }
        v.to_string()
    }

    /// Reads a request line; the error says what is missing or wrong.
    pub fn parse(line: &str) -> Result<Request, HubError> {
        let request: Value =
            serde_json::from_str(line).map_err(|e| invalid(format!("unreadable request: {e}")))?;
        let bad = |what: &str| invalid(format!("missing or invalid `{what}`"));
        let op = request["op"].as_str().unwrap_or_default();
        Ok(match op {
            "ping" => Request::Ping,
            "status" => Request::Status,
            "adapters" => Request::Adapters {
                user: user_adapters(&request)?,
            },
            "route" => Request::Route {
                id: request["id"].as_str().ok_or_else(|| bad("id"))?.to_string(),
                config: serde_json::from_value(request["config"].clone()).map_err(|e| {
                    HubError::InvalidConfig {
                        what: "config",
                        reason: e.to_string(),
                    }
                })?,
                user: user_adapters(&request)?,
            },
            "launch" => Request::Launch {
                job: serde_json::from_value(request["job"].clone()).map_err(|_| bad("job"))?,
                start_timeout: match &request["start_timeout_ms"] {
                    Value::Null => DEFAULT_START_TIMEOUT,
                    v => Duration::from_millis(v.as_u64().ok_or_else(|| bad("start_timeout_ms"))?),
                },
                user: user_adapters(&request)?,
            },
            "exit_status" => Request::ExitStatus {
                pid: request["pid"]
                    .as_u64()
                    .and_then(|p| u32::try_from(p).ok())
                    .ok_or_else(|| bad("pid"))?,
            },
            other => {
                return Err(invalid(format!(
                    "unknown op `{other}`; valid: ping, adapters, status, route, launch, exit_status"
                )));
            }
        })
    }
}

/// The client's user adapters of a request (none when the field is absent). Folders must be
/// absolute: the daemon's working directory is not the client's.
fn user_adapters(request: &Value) -> Result<UserAdapters, HubError> {
    let invalid = |reason: String| invalid(format!("invalid `user_adapters`: {reason}"));
    let user: UserAdapters = match request.get("user_adapters") {
        None | Some(Value::Null) => return Ok(UserAdapters::default()),
        Some(v) => serde_json::from_value(v.clone()).map_err(|e| {
            invalid(format!(
                "{e}; expected {{\"adapters\": [\"module:Class\"], \"pythonpath\": [\"/abs/dir\"]}}"
            ))
        })?,
    };
    if let Some(relative) = user.pythonpath.iter().find(|p| p.is_relative()) {
        return Err(invalid(format!(
            "`pythonpath` entry `{}` is relative; send absolute folders",
            relative.display()
        )));
    }
    Ok(user)
}

/// The reply line to a request that succeeded with `ok` or failed with `error`.
pub fn encode_reply(reply: &Result<Value, HubError>) -> String {
    match reply {
        Ok(ok) => json!({ "ok": ok }),
        // The text for people (and older clients), the error itself for clients to rebuild.
        Err(e) => json!({ "err": e.to_string(), "error": e }),
    }
    .to_string()
}

/// What a reply line that is not `ok` says.
#[derive(Debug)]
pub enum ReplyError {
    /// Not a reply at all (the reason).
    Unreadable(String),
    /// The daemon's error, as it had it (to be filtered by the caller).
    Error(HubError),
    /// An error as text only.
    Text(String),
}

/// Reads a reply line: the `ok` value (`null` when absent), or what went wrong.
pub fn parse_reply(line: &str) -> Result<Value, ReplyError> {
    let mut reply: Value =
        serde_json::from_str(line).map_err(|e| ReplyError::Unreadable(e.to_string()))?;
    if !reply.is_object() {
        return Err(ReplyError::Unreadable(format!(
            "a reply that is not an object: {}",
            truncated(&reply.to_string())
        )));
    }
    if let Some(error) = reply.get_mut("error").map(Value::take)
        && let Ok(error) = serde_json::from_value::<HubError>(error)
    {
        return Err(ReplyError::Error(error));
    }
    if let Some(err) = reply.get("err") {
        return Err(ReplyError::Text(
            err.as_str().unwrap_or("unknown error").to_string(),
        ));
    }
    Ok(reply.get_mut("ok").map(Value::take).unwrap_or(Value::Null))
}

fn truncated(text: &str) -> &str {
    let mut end = text.len().min(200);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    &text[..end]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_are_read_up_to_their_bound() {
        let mut input = std::io::Cursor::new(b"{\"op\":\"ping\"}\nxxxxxxxxxxxxxxxxxxxx\n".to_vec());
        let mut line = String::new();
        assert_eq!(read_line_bounded(&mut input, 16, &mut line).unwrap(), 14);
        assert_eq!(line, "{\"op\":\"ping\"}\n");
        let err = read_line_bounded(&mut input, 16, &mut line).unwrap_err();
        assert!(err.to_string().contains("longer than 16 bytes"), "{err}");
        let mut empty = std::io::Cursor::new(Vec::new());
        assert_eq!(read_line_bounded(&mut empty, 16, &mut line).unwrap(), 0);
    }

    #[test]
    fn requests_round_trip_and_bad_fields_are_named() {
        let user = UserAdapters {
            adapters: vec!["m:C".into()],
            pythonpath: vec!["/abs".into()],
        };
        let route = Request::Route {
            id: "gym-cartpole".into(),
            config: EnvConfig::default(),
            user: user.clone(),
        };
        match Request::parse(&route.encode()).unwrap() {
            Request::Route { id, user: back, .. } => {
                assert_eq!((id.as_str(), back), ("gym-cartpole", user))
            }
            other => panic!("{other:?}"),
        }
        let cases = [
            (r#"{"op": "exit_status", "pid": 4294967296}"#, "`pid`"),
            (r#"{"op": "route", "config": {}}"#, "`id`"),
            (r#"{"op": "launch", "job": {}}"#, "`job`"),
            (
                r#"{"op": "adapters", "user_adapters": {"pythonpath": ["rel"]}}"#,
                "is relative",
            ),
            (r#"{"op": "dance"}"#, "unknown op `dance`"),
            ("not json", "unreadable request"),
        ];
        for (line, want) in cases {
            let e = Request::parse(line).unwrap_err().to_string();
            assert!(e.contains(want), "{line}: {e}");
        }
    }

    #[test]
    fn replies_give_the_value_the_error_or_the_text() {
        let ok = encode_reply(&Ok(json!({"workers": 2})));
        assert_eq!(parse_reply(&ok).unwrap()["workers"], 2);
        let e = HubError::InvalidState("reset first".into());
        assert!(matches!(
            parse_reply(&encode_reply(&Err(e))),
            Err(ReplyError::Error(HubError::InvalidState(_)))
        ));
        assert!(matches!(
            parse_reply(r#"{"err": "old"}"#),
            Err(ReplyError::Text(t)) if t == "old"
        ));
        assert!(matches!(parse_reply("[1]"), Err(ReplyError::Unreadable(_))));
    }
}

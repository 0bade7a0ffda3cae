//! Task matching: from a plain-language task description to the best registry entry.
//!
//! The description is cut into task words; the words that mean something to the registry
//! (they match some entry's tags or robot model) are searched with the structured fields of
//! the spec, relaxing the filters step by step as RoboSmith does. The score is the share of
//! those words the chosen entry matches, so it is easy to explain in the reason. The
//! robot type is never relaxed; when it (or another filter) excludes the entry that would
//! be chosen without filters, the alternatives, or the no-match error, name it and say why.

use crate::entry::EnvEntry;
use crate::registry::{Registry, RegistryError, SearchHit, SearchQuery, matching_tags};
use crate::tags::words;
use serde::{Deserialize, Serialize};

/// What a user wants to train, in RoboSmith's terms.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TaskSpec {
    /// The task in plain language ("a quadruped runs forward").
    pub task_description: String,
    /// Robot morphology (`arm`, `quadruped`, ...).
    pub robot_type: Option<String>,
    /// Environment category (`tabletop`, `floor`, ...).
    pub environment_type: Option<String>,
    /// A registry id that overrides matching.
    pub environment_id: Option<String>,
    /// Restrict to one framework.
    pub framework: Option<String>,
    /// Specific robot model (`franka`).
    pub robot_model: Option<String>,
}

/// A ranked candidate.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Candidate {
    /// Registry id.
    pub id: String,
    /// Share of the task words matched, in [0, 1].
    pub score: f64,
    /// The task words it matched.
    pub matched_tags: Vec<String>,
    /// Set when the task's filters excluded it although it matches clearly more task words
    /// than the chosen entry: which filters, in words ("its robot type is \`custom\`, not
    /// \`biped\`").
    #[serde(skip_serializing_if = "Option::is_none")]
    pub excluded: Option<String>,
}

impl Candidate {
    /// The candidate in one line for people, out of `total` task words ("\`mujoco-hopper\`
    /// matches 2/2 task words (hop, forward)", then for an excluded one "but its robot type
    /// is \`custom\`, not \`biped\`").
    pub fn describe(&self, total: usize) -> String {
        let mut line = format!(
            "`{}` matches {}/{} task words ({})",
            self.id,
            self.matched_tags.len(),
            total,
            self.matched_tags.join(", ")
        );
        if let Some(why) = &self.excluded {
            line.push_str(&format!(" but {why}"));
        }
        line
    }
}

/// The best entry for a task, why, and the runners-up.
#[derive(Clone, Debug)]
pub struct TaskMatch<'a> {
    /// The chosen entry.
    pub entry: &'a EnvEntry,
    /// Share of the task words matched, in [0, 1] (1 for an explicit id).
    pub score: f64,
    /// For people: which words matched, and which filters were used or relaxed.
    pub reason: String,
    /// Other candidates, best first.
    pub alternatives: Vec<Candidate>,
}

/// Why no entry fits.
#[derive(Debug, thiserror::Error)]
pub enum MatchError {
    /// The explicit `environment_id` does not exist.
    #[error(transparent)]
    UnknownId(#[from] RegistryError),
    /// Nothing fits well enough.
    #[error("no environment matches the task: {why}\nhint: {hint}")]
    NoMatch {
        /// What was tried.
        why: String,
        /// What to try.
        hint: String,
    },
}

/// How many runners-up a match reports.
const MAX_ALTERNATIVES: usize = 5;

/// How many of the runners-up may be entries the task's filters excluded.
const MAX_EXCLUDED: usize = 2;

/// Once a filter the user gave has been relaxed, the match must cover at least this share of
/// the task words: the user asked for something else, so weak word overlap is not enough.
const MIN_RELAXED_SCORE: f64 = 0.5;

/// Finds the best entry of `registry` for `spec`.
///
/// Order: an explicit `environment_id`; a search with every structured field and the task
/// words; the same without the environment type; then robot type and task words only.
/// A candidate that matches none of the task words is rejected rather than guessed.
pub fn match_task<'a>(
    spec: &TaskSpec,
    registry: &'a Registry,
) -> Result<TaskMatch<'a>, MatchError> {
    if let Some(id) = spec
        .environment_id
        .as_deref()
        .filter(|id| !id.trim().is_empty())
    {
        return explicit(id.trim(), registry);
    }
    let words = TaskWords::of(spec, registry)?;
    let mut rejected: Option<String> = None;
    let mut previous: Option<SearchQuery> = None;
    for attempt in attempts(spec, &words.tags) {
        // A relaxation that drops nothing would repeat the search before it.
        if previous.as_ref() == Some(&attempt.query) {
            continue;
        }
        let hits = registry.search(&attempt.query);
        previous = Some(attempt.query.clone());
        let Some(best) = hits.first() else { continue };
        if attempt.relaxed && words.score(best.matched_tags.len()) < MIN_RELAXED_SCORE {
            rejected.get_or_insert_with(|| {
                format!(
                    "the closest entry, `{}`, matches only {}/{} task words ({}){}",
                    best.entry.id,
                    best.matched_tags.len(),
                    words.total(),
                    best.matched_tags.join(", "),
                    attempt.how
                )
            });
            continue;
        }
        return Ok(chosen(&words, registry, &attempt, &hits));
    }
    Err(no_match(spec, registry, &words, rejected, previous))
}

/// Phase 1: the entry asked for by id, whatever the description says.
fn explicit<'a>(id: &str, registry: &'a Registry) -> Result<TaskMatch<'a>, MatchError> {
    let entry = registry.get(id)?;
    Ok(TaskMatch {
        entry,
        score: 1.0,
        reason: format!("environment `{}` was requested explicitly", entry.id),
        alternatives: Vec::new(),
    })
}

/// Phase 2: the description's words, and those of them the registry knows (the tags
/// searched for).
struct TaskWords {
    said: Vec<String>,
    tags: Vec<String>,
}

impl TaskWords {
    /// The words of `spec`'s description; an error when none means anything to `registry`.
    fn of(spec: &TaskSpec, registry: &Registry) -> Result<TaskWords, MatchError> {
        let said = words(&spec.task_description);
        let tags = known_words(&said, registry);
        if tags.is_empty() {
            return Err(MatchError::NoMatch {
                why: if said.is_empty() {
                    "the description has no task words".to_string()
                } else {
                    format!(
                        "none of its words ({}) match a tag or robot model in the registry",
                        said.join(", ")
                    )
                },
                hint: "describe the task with words such as walk, run, reach, push, pick, place, balance, or pass `--id`".to_string(),
            });
        }
        Ok(TaskWords { said, tags })
    }

    /// Every word of the description counts, known to the registry or not: a task that is
    /// mostly about things no entry offers ("a submarine in a reef") must not score high.
    fn total(&self) -> usize {
        self.said.len()
    }

    /// The score of an entry matching `n` task words (a share, rounded to hundredths).
    fn score(&self, n: usize) -> f64 {
        (n as f64 / self.total() as f64 * 100.0).round() / 100.0
    }
}

/// One search of phase 3: its query, how to describe its filters, and whether it relaxed
/// one the user gave.
struct Attempt {
    how: String,
    query: SearchQuery,
    relaxed: bool,
}

/// Phase 3: the searches, strictest first: every field; without the environment type;
/// robot type and task words only (the robot type is never relaxed).
fn attempts(spec: &TaskSpec, tags: &[String]) -> [Attempt; 3] {
    let full = SearchQuery {
        robot_type: spec.robot_type.clone(),
        env_type: spec.environment_type.clone(),
        framework: spec.framework.clone(),
        robot_model: spec.robot_model.clone(),
        action_type: None,
        tags: tags.to_vec(),
    };
    let without_env_type = SearchQuery {
        env_type: None,
        ..full.clone()
    };
    let robot_and_tags = SearchQuery {
        robot_type: spec.robot_type.clone(),
        tags: tags.to_vec(),
        ..SearchQuery::default()
    };
    [
        Attempt {
            how: given(&full),
            query: full,
            relaxed: false,
        },
        Attempt {
            how: format!("{} (environment type relaxed)", given(&without_env_type)),
            query: without_env_type,
            relaxed: true,
        },
        Attempt {
            how: format!("{} (other filters relaxed)", given(&robot_and_tags)),
            query: robot_and_tags,
            relaxed: true,
        },
    ]
}

/// The structured filters of `query` in words (" with robot type \`arm\`, ..."), or nothing.
fn given(query: &SearchQuery) -> String {
    let fields: Vec<String> = [
        ("robot type", &query.robot_type),
        ("environment type", &query.env_type),
        ("framework", &query.framework),
        ("model", &query.robot_model),
    ]
    .iter()
    .filter_map(|(name, v)| v.as_ref().map(|v| format!("{name} `{v}`")))
    .collect();
    if fields.is_empty() {
        String::new()
    } else {
        format!(" with {}", fields.join(", "))
    }
}

/// Phase 4: the match for the best of `hits` (found by `attempt`), with the runners-up and
/// why it was chosen.
fn chosen<'a>(
    words: &TaskWords,
    registry: &'a Registry,
    attempt: &Attempt,
    hits: &[SearchHit<'a>],
) -> TaskMatch<'a> {
    let best = &hits[0];
    let mut alternatives =
        excluded_better(words, registry, &attempt.query, best.matched_tags.len());
    alternatives.extend(
        hits.iter()
            .skip(1)
            .take(MAX_ALTERNATIVES - alternatives.len())
            .map(|h| Candidate {
                id: h.entry.id.clone(),
                score: words.score(h.matched_tags.len()),
                matched_tags: h.matched_tags.clone(),
                excluded: None,
            }),
    );
    let unmatched: Vec<&str> = words
        .said
        .iter()
        .filter(|w| !best.matched_tags.contains(w))
        .map(String::as_str)
        .collect();
    let mut reason = format!(
        "matched {}/{} task words ({}){}",
        best.matched_tags.len(),
        words.total(),
        best.matched_tags.join(", "),
        attempt.how
    );
    if !unmatched.is_empty() {
        reason.push_str(&format!("; not matched: {}", unmatched.join(", ")));
    }
    TaskMatch {
        entry: best.entry,
        score: words.score(best.matched_tags.len()),
        reason,
        alternatives,
    }
}

/// The entries that would be chosen without any filter, when the filters of `query`
/// exclude them and they match more task words than `matched` (and at least half of
/// them): the user should hear about them.
fn excluded_better(
    words: &TaskWords,
    registry: &Registry,
    query: &SearchQuery,
    matched: usize,
) -> Vec<Candidate> {
    let any = SearchQuery {
        tags: words.tags.clone(),
        ..SearchQuery::default()
    };
    let hits = registry.search(&any);
    let top = hits.first().map_or(0, |h| h.matched_tags.len());
    if top <= matched || words.score(top) < MIN_RELAXED_SCORE {
        return Vec::new();
    }
    hits.into_iter()
        .take_while(|h| h.matched_tags.len() == top)
        .filter_map(|h| {
            let unmet = query.unmet_filters(h.entry);
            (!unmet.is_empty()).then(|| Candidate {
                id: h.entry.id.clone(),
                score: words.score(h.matched_tags.len()),
                matched_tags: h.matched_tags,
                excluded: Some(unmet.join(" and ")),
            })
        })
        .take(MAX_EXCLUDED)
        .collect()
}

/// Phase 5: no search found a good enough entry: say what was tried (`rejected`: the
/// closest entry a relaxed search refused; `loosest`: the last search made), which entries
/// the filters excluded, and what the registry offers.
fn no_match(
    spec: &TaskSpec,
    registry: &Registry,
    words: &TaskWords,
    rejected: Option<String>,
    loosest: Option<SearchQuery>,
) -> MatchError {
    let filters: Vec<String> = [
        ("robot type", &spec.robot_type),
        ("environment type", &spec.environment_type),
        ("framework", &spec.framework),
        ("model", &spec.robot_model),
    ]
    .iter()
    .filter_map(|(name, v)| v.as_ref().map(|v| format!("{name} `{v}`")))
    .collect();
    let mut why = rejected.unwrap_or_else(|| {
        format!(
            "no entry{} matches any of the task words ({})",
            if filters.is_empty() {
                String::new()
            } else {
                format!(" with {}", filters.join(", "))
            },
            words.tags.join(", ")
        )
    });
    // The loosest search tried keeps the robot type: entries that only it excluded.
    let excluded = loosest.map_or_else(Vec::new, |q| excluded_better(words, registry, &q, 0));
    let mut hint = String::new();
    if !excluded.is_empty() {
        for c in &excluded {
            why.push_str(&format!("; {}", c.describe(words.total())));
        }
        hint = format!(
            "change or leave out the filter that excludes `{}`; ",
            excluded[0].id
        );
    }
    hint.push_str(&format!(
        "robot types in the registry: {}; environment types: {}",
        registry.robot_types().join(", "),
        registry.distinct("env_type").join(", ")
    ));
    MatchError::NoMatch { why, hint }
}

/// The words of a description that some entry of the registry can match.
fn known_words(said: &[String], registry: &Registry) -> Vec<String> {
    said.iter()
        .filter(|w| {
            let one = std::slice::from_ref(*w);
            registry
                .entries()
                .iter()
                .any(|e| !matching_tags(e, one).is_empty())
        })
        .cloned()
        .collect()
}

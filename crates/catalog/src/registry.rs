//! The environment registry: YAML catalogs loaded, combined, looked up and searched.

use crate::entry::EnvEntry;
pub use crate::python_envs::LockSource;
use crate::registry_error::id_lines;
pub use crate::registry_error::{DEFAULT_REGISTRY_NAME, RegistryError};
use crate::tags::{stem, stems_match, tag_stems};
use envhub_core::canonical_framework;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The catalog that ships with envhub, compiled in so the binary works from anywhere.
const DEFAULT_REGISTRY: &str = include_str!("../../../configs/env_registry.yaml");
/// Its lock file (`envhub env lock` in a checkout rewrites it; a rebuild ships it).
const DEFAULT_LOCK: &str = include_str!("../../../configs/env_registry.lock.yaml");

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RegistryFile {
    environments: Vec<EnvEntry>,
    #[serde(default)]
    python_envs: std::collections::BTreeMap<String, crate::python_env_spec::PythonEnvSpec>,
    #[serde(default)]
    frameworks: std::collections::BTreeMap<String, crate::python_envs::FrameworkDefaults>,
    /// Evaluation protocols (`envhub eval`). Kept as written: the evaluation (in the Python
    /// package) validates them, naming the valid fields, when one is used.
    #[serde(default)]
    benchmarks: std::collections::BTreeMap<String, serde_json::Value>,
}

/// Filters for [`Registry::search`]. Every filter is a case-insensitive substring; empty
/// filters are ignored; all given filters must hold.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SearchQuery {
    /// Robot type (`quad` matches `quadruped`).
    pub robot_type: Option<String>,
    /// Environment type.
    pub env_type: Option<String>,
    /// Framework (`gym` matches `gymnasium`; aliases such as `isaaclab` are understood).
    pub framework: Option<String>,
    /// Robot model.
    pub robot_model: Option<String>,
    /// Action type.
    pub action_type: Option<String>,
    /// Task words: an entry must match at least one; results are sorted by how many match.
    pub tags: Vec<String>,
}

impl SearchQuery {
    /// The filters of this query that `entry` fails, in words ("its robot type is
    /// \`custom\`, not \`biped\`"); empty when it passes them all. Task words are not
    /// filters.
    pub(crate) fn unmet_filters(&self, entry: &EnvEntry) -> Vec<String> {
        let filters = [
            ("robot type", "robot_type", &self.robot_type),
            ("environment type", "env_type", &self.env_type),
            ("framework", "framework", &self.framework),
            ("robot model", "robot_model", &self.robot_model),
            ("action type", "action_type", &self.action_type),
        ];
        filters
            .iter()
            .filter_map(|(name, field, wanted)| {
                let wanted = wanted.as_deref().filter(|v| !v.trim().is_empty())?;
                let value = entry.field(field);
                let passes = if *field == "framework" {
                    framework_matches(value, wanted)
                } else {
                    contains_ci(value, wanted)
                };
                (!passes).then(|| format!("its {name} is `{value}`, not `{}`", wanted.trim()))
            })
            .collect()
    }
}

/// One search result.
#[derive(Clone, Debug)]
pub struct SearchHit<'a> {
    /// The entry.
    pub entry: &'a EnvEntry,
    /// The query tags it matched (as given in the query).
    pub matched_tags: Vec<String>,
}

/// A searchable catalog of environments, in file order.
#[derive(Clone, Debug, Default)]
pub struct Registry {
    entries: Vec<EnvEntry>,
    sources: Vec<String>,
    python_envs: crate::python_envs::PythonEnvs,
    benchmarks: std::collections::BTreeMap<String, Benchmark>,
}

/// A benchmark as a registry file declares it (`benchmarks:`), with the file it came from.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Benchmark {
    /// The fields as written.
    #[serde(flatten)]
    pub fields: serde_json::Map<String, serde_json::Value>,
    /// The registry file that declares it (later files replace a name).
    pub source: String,
}

impl Registry {
    /// The built-in catalog (`configs/env_registry.yaml`).
    pub fn builtin() -> Registry {
        let mut registry = Registry::default();
        registry
            .add_builtin()
            .expect("the built-in registry is valid (checked by tests)");
        registry
    }

    /// A registry of `entries` as another hub sent them (`source` names it in messages).
    pub fn from_entries(entries: Vec<EnvEntry>, source: &str) -> Registry {
        Registry {
            entries,
            sources: vec![source.to_string()],
            python_envs: Default::default(),
            benchmarks: Default::default(),
        }
    }

    /// Loads and combines registry files, in order. `@default` stands for the built-in
    /// catalog. An id that appears in a later file replaces the earlier entry in place (so a
    /// user's file can override a default entry without reordering the catalog); within one
    /// file, a repeated id is an error.
    pub fn load<P: AsRef<Path>>(paths: &[P]) -> Result<Registry, RegistryError> {
        let mut registry = Registry::default();
        for path in paths {
            let path = path.as_ref();
            if path == Path::new(DEFAULT_REGISTRY_NAME) {
                registry.add_builtin()?;
                continue;
            }
            let text = std::fs::read_to_string(path).map_err(|source| RegistryError::Read {
                path: path.to_path_buf(),
                source,
            })?;
            let dir = path.parent().unwrap_or(Path::new("."));
            let lock_path = crate::env_lock::lock_path(path);
            let file = match std::fs::read_to_string(&lock_path) {
                Ok(text) => Some(lock_error(&lock_path.display().to_string(), &text)?),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
                Err(source) => {
                    return Err(RegistryError::Read {
                        path: lock_path,
                        source,
                    });
                }
            };
            let lock = LockSource {
                name: lock_path.display().to_string(),
                path: Some(lock_path),
                file,
            };
            registry.add_yaml_locked(&text, &path.display().to_string(), dir, &lock)?;
        }
        Ok(registry)
    }

    /// Parses one registry file's text and merges it in. `base_dir` anchors relative
    /// `asset_path`s; `name` is used in error messages.
    pub fn add_yaml(
        &mut self,
        text: &str,
        name: &str,
        base_dir: &Path,
    ) -> Result<(), RegistryError> {
        self.add_yaml_locked(text, name, base_dir, &LockSource::default())
    }

    /// The built-in catalog with its lock. Its lock file is written (by `envhub env lock`)
    /// into `configs/` of the current folder when that is an envhub checkout of this very
    /// catalog; elsewhere there is nowhere to write it.
    fn add_builtin(&mut self) -> Result<(), RegistryError> {
        let name = builtin_name();
        let lock_name = format!("configs/env_registry.lock.yaml ({DEFAULT_REGISTRY_NAME})");
        let in_checkout = std::fs::read_to_string("configs/env_registry.yaml")
            .is_ok_and(|text| text == DEFAULT_REGISTRY);
        let lock = LockSource {
            path: in_checkout.then(|| PathBuf::from("configs/env_registry.lock.yaml")),
            file: Some(lock_error(&lock_name, DEFAULT_LOCK)?),
            name: lock_name,
        };
        self.add_yaml_locked(
            DEFAULT_REGISTRY,
            &name,
            &crate::builtin_assets::builtin_dir()
                .map_err(|message| RegistryError::Assets { message })?,
            &lock,
        )
    }

    /// [`add_yaml`](Registry::add_yaml) with the file's lock file (see
    /// [`LockSource`]): its environments are then locked, or unlocked where it has none.
    pub fn add_yaml_locked(
        &mut self,
        text: &str,
        name: &str,
        base_dir: &Path,
        lock: &LockSource,
    ) -> Result<(), RegistryError> {
        let file = parse(text, name)?;
        self.python_envs.add_file(
            file.python_envs,
            file.frameworks,
            &file.environments,
            text,
            name,
            lock,
        )?;
        for (name_of, value) in file.benchmarks {
            let serde_json::Value::Object(fields) = value else {
                return Err(RegistryError::Benchmark {
                    path: name.to_string(),
                    line: text
                        .lines()
                        .position(|l| l.trim_start().starts_with(&format!("{name_of}:")))
                        .map_or(0, |i| i + 1),
                    message: format!(
                        "`benchmarks.{name_of}`: a benchmark is a mapping of its fields (entries, episodes_per_task, horizon, ...)"
                    ),
                });
            };
            self.benchmarks.insert(
                name_of,
                Benchmark {
                    fields,
                    source: name.to_string(),
                },
            );
        }
        let entries = file.environments;
        let mut seen = std::collections::HashSet::new();
        for (index, mut entry) in entries.into_iter().enumerate() {
            validate(&entry, index, text, name)?;
            if !seen.insert(entry.id.clone()) {
                let lines = id_lines(text, &entry.id);
                return Err(RegistryError::DuplicateId {
                    path: name.to_string(),
                    id: entry.id,
                    line: lines.get(1).copied().unwrap_or(0),
                    first_line: lines.first().copied().unwrap_or(0),
                });
            }
            if let Some(asset) = &entry.asset_path
                && asset.is_relative()
            {
                entry.asset_path = Some(base_dir.join(asset));
            }
            match self.entries.iter_mut().find(|e| e.id == entry.id) {
                Some(existing) => {
                    tracing::debug!(id = %entry.id, file = name, "registry entry overridden");
                    *existing = entry;
                }
                None => self.entries.push(entry),
            }
        }
        self.sources.push(name.to_string());
        Ok(())
    }

    /// The Python environments its files declare (`python_envs:`, `frameworks:`).
    pub fn python_envs(&self) -> &crate::python_envs::PythonEnvs {
        &self.python_envs
    }

    /// The benchmarks its files declare (`benchmarks:`), by name; a later file's replaces an
    /// earlier one of the same name.
    pub fn benchmarks(&self) -> &std::collections::BTreeMap<String, Benchmark> {
        &self.benchmarks
    }

    /// The files this registry was built from, in order.
    pub fn sources(&self) -> &[String] {
        &self.sources
    }

    /// The entry with this id, or an error naming the closest ids.
    pub fn get(&self, id: &str) -> Result<&EnvEntry, RegistryError> {
        self.entries
            .iter()
            .find(|e| e.id == id)
            .ok_or_else(|| RegistryError::UnknownId {
                id: id.to_string(),
                closest: self.closest_ids(id),
            })
    }

    /// Up to three ids close to `id` (by spelling, or matching its `env_id`).
    pub fn closest_ids(&self, id: &str) -> Vec<String> {
        let by_env_id: Vec<String> = self
            .entries
            .iter()
            .filter(|e| e.env_id.eq_ignore_ascii_case(id))
            .map(|e| e.id.clone())
            .collect();
        if !by_env_id.is_empty() {
            return by_env_id;
        }
        envhub_core::closest(id, self.entries.iter().map(|e| e.id.as_str()), 3)
    }

    /// Every entry, in file order.
    pub fn entries(&self) -> &[EnvEntry] {
        &self.entries
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether the registry is empty.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Distinct values of a field (`framework`, `robot_type`, `robot_model`, `env_type`,
    /// `action_type`, `obs_type`), sorted.
    pub fn distinct(&self, field: &str) -> Vec<String> {
        let mut values: Vec<String> = self
            .entries
            .iter()
            .map(|e| e.field(field).to_string())
            .filter(|v| !v.is_empty())
            .collect();
        values.sort();
        values.dedup();
        values
    }

    /// Distinct frameworks, sorted.
    pub fn frameworks(&self) -> Vec<String> {
        self.distinct("framework")
    }

    /// Distinct robot types, sorted.
    pub fn robot_types(&self) -> Vec<String> {
        self.distinct("robot_type")
    }

    /// Entries that pass every filter of `query`; with tags, only entries matching at least
    /// one tag, sorted by the number matched (ties keep file order).
    pub fn search(&self, query: &SearchQuery) -> Vec<SearchHit<'_>> {
        let mut hits: Vec<SearchHit<'_>> = self
            .entries
            .iter()
            .filter(|e| query.unmet_filters(e).is_empty())
            .map(|e| SearchHit {
                entry: e,
                matched_tags: matching_tags(e, &query.tags),
            })
            .collect();
        let tags: Vec<&String> = query.tags.iter().filter(|t| !t.trim().is_empty()).collect();
        if !tags.is_empty() {
            hits.retain(|h| !h.matched_tags.is_empty());
            // Stable sort: equal scores stay in file order.
            hits.sort_by_key(|h| std::cmp::Reverse(h.matched_tags.len()));
        }
        hits
    }
}

/// A lock file parsed, or the error naming it.
fn lock_error(name: &str, text: &str) -> Result<crate::env_lock::LockFile, RegistryError> {
    crate::env_lock::LockFile::parse(text).map_err(|message| RegistryError::PythonEnv {
        path: name.to_string(),
        line: 0,
        message: format!(
            "invalid lock file: {message}\nhint: regenerate it with `envhub env lock`"
        ),
    })
}

fn builtin_name() -> String {
    format!("configs/env_registry.yaml ({DEFAULT_REGISTRY_NAME})")
}

fn contains_ci(haystack: &str, needle: &str) -> bool {
    haystack
        .to_lowercase()
        .contains(&needle.trim().to_lowercase())
}

/// Substring match as RoboSmith does (`gym` finds `gymnasium`), plus aliases
/// (`isaaclab` finds `isaac_lab`, `mjcf` finds `custom_mjcf`).
fn framework_matches(entry_framework: &str, query: &str) -> bool {
    if contains_ci(entry_framework, query) {
        return true;
    }
    match (
        canonical_framework(query),
        canonical_framework(entry_framework),
    ) {
        (Some(q), Some(e)) => q == e,
        _ => false,
    }
}

/// The query tags an entry matches, through its tags' stems and its robot model.
pub(crate) fn matching_tags(entry: &EnvEntry, tags: &[String]) -> Vec<String> {
    let mut offered: Vec<String> = entry.task_tags.iter().flat_map(|t| tag_stems(t)).collect();
    offered.extend(tag_stems(&entry.robot_model));
    let mut matched = Vec::new();
    for tag in tags {
        let tag = tag.trim();
        if tag.is_empty() || matched.iter().any(|m: &String| m.eq_ignore_ascii_case(tag)) {
            continue;
        }
        let query_stems = tag_stems(tag);
        let whole = stem(tag);
        let hit = if query_stems.len() > 1 {
            // A compound query tag (`pick-and-place`) matches an entry's identical compound.
            offered.contains(&whole)
        } else {
            offered.iter().any(|o| stems_match(o, &whole))
        };
        if hit {
            matched.push(tag.to_lowercase());
        }
    }
    matched
}

fn parse(text: &str, name: &str) -> Result<RegistryFile, RegistryError> {
    serde_norway::from_str::<RegistryFile>(text)
        .map_err(|err| {
            let (line, column) = err
                .location()
                .map(|l| (l.line(), l.column()))
                .unwrap_or((0, 0));
            let mut message = err.to_string();
            if let Some(at) = message.rfind(" at line ") {
                message.truncate(at);
            }
            let hint = if message.contains("unknown field") {
                "remove or rename the field; the valid ones are listed above"
            } else if message.contains("missing field") {
                "every entry needs `id`, `name`, `framework`, `env_id`, `robot_type` and `env_type`"
            } else if message.contains("invalid type") {
                "`task_tags` is a list of words, `kwargs` a mapping, `max_episode_steps` a positive integer, other fields are text"
            } else {
                "the file must be a YAML mapping with an `environments:` list of entries"
            };
            RegistryError::Parse {
                path: name.to_string(),
                line,
                column,
                message,
                hint: hint.to_string(),
            }
        })
}

fn validate(entry: &EnvEntry, index: usize, text: &str, name: &str) -> Result<(), RegistryError> {
    // The line is looked up only for an error: scanning the text for every valid entry
    // would make each load quadratic in the file's length.
    let invalid = |field: &'static str, message: String| RegistryError::Invalid {
        path: name.to_string(),
        line: id_lines(text, &entry.id).first().copied().unwrap_or(0),
        index,
        field,
        message,
    };
    if entry.id.trim().is_empty() || entry.id.chars().any(char::is_whitespace) {
        return Err(invalid(
            "id",
            format!(
                "`{}` is not a valid id; use letters, digits and dashes (`my-env`)",
                entry.id
            ),
        ));
    }
    for (field, value) in [
        ("name", &entry.name),
        ("framework", &entry.framework),
        ("env_id", &entry.env_id),
        ("robot_type", &entry.robot_type),
        ("env_type", &entry.env_type),
    ] {
        if value.trim().is_empty() {
            return Err(invalid(
                field,
                format!("must not be empty (entry `{}`)", entry.id),
            ));
        }
    }
    if entry.max_episode_steps == Some(0) {
        return Err(invalid(
            "max_episode_steps",
            format!(
                "must be a positive integer (entry `{}`); leave it out to keep the framework's default",
                entry.id
            ),
        ));
    }
    Ok(())
}

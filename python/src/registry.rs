//! `Registry`: the catalog, searched and matched by the Rust code, handed to Python as JSON
//! (the pure-Python layer turns entries into objects with the YAML fields as attributes).

use crate::errors::{hub_error, match_error, raise, registry_error};
use envhub_hub::{HubError, Registry, SearchQuery, Settings, TaskSpec};
use pyo3::prelude::*;
use std::path::PathBuf;

/// Fields whose distinct values can be listed.
const FIELDS: &[&str] = &[
    "framework",
    "robot_type",
    "robot_model",
    "env_type",
    "action_type",
    "obs_type",
];

/// A loaded registry.
#[pyclass(name = "Registry", module = "envhub._envhub", frozen)]
pub(crate) struct PyRegistry {
    pub(crate) inner: Registry,
}

#[pymethods]
impl PyRegistry {
    /// The registry chosen the usual way: `ENVHUB_REGISTRY`, `envhub.yaml`, else the built-in one.
    #[staticmethod]
    fn discover(py: Python<'_>) -> PyResult<PyRegistry> {
        let settings = Settings::discover(None).map_err(|e| {
            hub_error(
                py,
                HubError::InvalidConfig {
                    what: "config file",
                    reason: e.to_string(),
                },
            )
        })?;
        let inner = settings.registry(&[]).map_err(|e| registry_error(py, e))?;
        Ok(PyRegistry { inner })
    }

    /// Registry files combined in order (`@default` is the built-in catalog).
    #[staticmethod]
    fn load(py: Python<'_>, paths: Vec<PathBuf>) -> PyResult<PyRegistry> {
        let inner = Registry::load(&paths).map_err(|e| registry_error(py, e))?;
        Ok(PyRegistry { inner })
    }

    /// Every entry as a JSON array, in file order.
    fn entries_json(&self) -> String {
        serde_json::to_string(self.inner.entries()).expect("entries serialize")
    }

    /// The benchmarks the files declare (`benchmarks:`) as a JSON object: name → the fields
    /// as written, plus `source`, the file that declares it.
    fn benchmarks_json(&self) -> String {
        serde_json::to_string(self.inner.benchmarks()).expect("benchmarks serialize")
    }

    /// One entry as JSON; an unknown id raises `UnknownEnvError` with the closest ids.
    fn get_json(&self, py: Python<'_>, id: &str) -> PyResult<String> {
        let entry = self.inner.get(id).map_err(|e| registry_error(py, e))?;
        Ok(serde_json::to_string(entry).expect("entry serializes"))
    }

    /// The Python environment (`python_envs:`) entry `id`'s workers run in: its own, else
    /// its framework's; None where they run in the hub's interpreter.
    fn python_env_of(&self, py: Python<'_>, id: &str) -> PyResult<Option<String>> {
        let entry = self.inner.get(id).map_err(|e| registry_error(py, e))?;
        Ok(self.inner.python_envs().name_for(entry).map(str::to_owned))
    }

    /// Search results as JSON: `[{"entry": {...}, "matched_tags": [...]}, ...]`.
    #[pyo3(signature = (robot_type=None, env_type=None, framework=None, robot_model=None, action_type=None, tags=Vec::new()))]
    fn search_json(
        &self,
        robot_type: Option<String>,
        env_type: Option<String>,
        framework: Option<String>,
        robot_model: Option<String>,
        action_type: Option<String>,
        tags: Vec<String>,
    ) -> String {
        let query = SearchQuery {
            robot_type,
            env_type,
            framework,
            robot_model,
            action_type,
            tags,
        };
        let hits: Vec<serde_json::Value> = self
            .inner
            .search(&query)
            .iter()
            .map(|h| serde_json::json!({"entry": h.entry, "matched_tags": h.matched_tags}))
            .collect();
        serde_json::Value::Array(hits).to_string()
    }

    /// Distinct values of a field, sorted.
    fn distinct(&self, py: Python<'_>, field: &str) -> PyResult<Vec<String>> {
        if !FIELDS.contains(&field) {
            return Err(raise(
                py,
                "InvalidConfigError",
                format!(
                    "cannot list values of `{field}`; fields with values to list are {}",
                    FIELDS.join(", ")
                ),
                vec![],
            ));
        }
        Ok(self.inner.distinct(field))
    }

    /// The files this registry was built from.
    fn sources(&self) -> Vec<String> {
        self.inner.sources().to_vec()
    }

    fn __len__(&self) -> usize {
        self.inner.len()
    }

    /// The best entry for a task (`TaskSpec` as JSON), as JSON: entry, score, reason,
    /// alternatives.
    fn match_task_json(&self, py: Python<'_>, spec_json: &str) -> PyResult<String> {
        let spec: TaskSpec = serde_json::from_str(spec_json).map_err(|e| {
            raise(
                py,
                "InvalidConfigError",
                format!("invalid task spec: {e}"),
                vec![],
            )
        })?;
        let found = envhub_hub::match_task(&spec, &self.inner).map_err(|e| match_error(py, e))?;
        Ok(serde_json::json!({
            "entry": found.entry,
            "score": found.score,
            "reason": found.reason,
            "alternatives": found.alternatives,
        })
        .to_string())
    }
}

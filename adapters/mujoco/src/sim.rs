//! `Sim`: one MuJoCo model and its data, stepped the way Gymnasium's `MujocoEnv` steps them.

use envhub_core::EnvError;
use mujoco_rs::prelude::*;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, Once};

/// Models loaded by an adapter, by file and offscreen buffer size: every env of a worker that
/// uses the same file shares one read-only `MjModel` (MuJoCo never writes to it while
/// stepping), so creating the eighth Ant costs an `MjData`, not an XML parse.
#[derive(Default)]
pub(crate) struct ModelCache {
    models: Mutex<HashMap<ModelKey, Arc<MjModel>>>,
}

/// A model file and the offscreen buffer size it was loaded with.
type ModelKey = (PathBuf, Option<(u32, u32)>);

impl ModelCache {
    /// The model in `path`; with `offscreen`, its offscreen buffer grown to at least that
    /// size (as Gymnasium grows it to the render size).
    pub(crate) fn load(
        &self,
        path: &Path,
        offscreen: Option<(u32, u32)>,
    ) -> Result<Arc<MjModel>, EnvError> {
        let key = (path.to_path_buf(), offscreen);
        let mut models = self.models.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(model) = models.get(&key) {
            return Ok(model.clone());
        }
        let mut model = load_model(path)?;
        if let Some((width, height)) = offscreen {
            // SAFETY: plain integer fields of a model no one else holds yet.
            let global = unsafe { &mut model.ffi_mut().vis.global };
            global.offwidth = global.offwidth.max(width as i32);
            global.offheight = global.offheight.max(height as i32);
        }
        let model = Arc::new(model);
        models.insert(key, model.clone());
        Ok(model)
    }
}

/// Loads an MJCF or URDF file; an error carries the path and MuJoCo's own message (which names
/// the line of an XML error).
pub(crate) fn load_model(path: &Path) -> Result<MjModel, EnvError> {
    route_mujoco_log();
    let asset_error = |reason: String| EnvError::Asset {
        path: path.display().to_string(),
        reason,
    };
    if !path.is_file() {
        return Err(asset_error(if path.exists() {
            "not a file".into()
        } else {
            "no such file".into()
        }));
    }
    MjModel::from_xml(path).map_err(|e| {
        asset_error(match e {
            MjModelError::LoadFailed(msg) => {
                let msg = full_load_error(path).unwrap_or(msg);
                format!("MuJoCo: {}", msg.trim())
            }
            other => other.to_string(),
        })
    })
}

/// MuJoCo's whole message for a model that fails to load: mujoco-rs keeps only its first 100
/// characters, which can cut off the element and line at fault, so this loads the file again
/// with room for all of it.
fn full_load_error(path: &Path) -> Option<String> {
    use mujoco_rs::mujoco_c::{mj_deleteModel, mj_loadXML};
    use std::ffi::{CStr, CString, c_char};
    let path = CString::new(path.to_str()?).ok()?;
    let mut buf = [0 as c_char; 2048];
    // SAFETY: a NUL-terminated path, no VFS, and a buffer whose size is passed along; MuJoCo
    // NUL-terminates what it writes.
    let model = unsafe { mj_loadXML(path.as_ptr(), std::ptr::null(), buf.as_mut_ptr(), 2048) };
    if !model.is_null() {
        // SAFETY: a model MuJoCo just allocated and no one else holds.
        unsafe { mj_deleteModel(model) };
        return None;
    }
    // SAFETY: see above.
    let text = unsafe { CStr::from_ptr(buf.as_ptr()) };
    Some(text.to_string_lossy().into_owned()).filter(|t| !t.is_empty())
}

/// Sends MuJoCo's own messages (model warnings, unstable simulations) to `tracing` instead of
/// MuJoCo's default, which prints to stdout — in a worker, the control channel to the hub —
/// and appends to `MUJOCO_LOG.TXT` in the current directory. Runs before the first model load,
/// which comes before any other use of MuJoCo in this crate.
fn route_mujoco_log() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // SAFETY: `Once` holds every other thread of this crate at this point, and all of them
        // reach MuJoCo only through a model loaded after it; the handler is thread-safe and
        // never panics.
        unsafe { set_log_handler(on_mujoco_log) };
    });
}

fn on_mujoco_log(message: &MjLogMessage) {
    let text = message.subject();
    match message.level() {
        MjtLogLevel::mjLOG_ERROR => tracing::error!(target: "mujoco", "{text}"),
        // Deprecation notes concern the model's author (Gymnasium's own assets trigger
        // some); the user of the env cannot act on them.
        MjtLogLevel::mjLOG_WARNING if text.contains("deprecated") => {
            tracing::debug!(target: "mujoco", "{text}")
        }
        MjtLogLevel::mjLOG_WARNING => tracing::warn!(target: "mujoco", "{text}"),
        MjtLogLevel::mjLOG_INFO => tracing::info!(target: "mujoco", "{text}"),
        MjtLogLevel::mjLOG_DEBUG => {}
    }
}

/// A model, its data, and how many MuJoCo steps one env step takes.
pub(crate) struct Sim {
    pub(crate) data: MjData<Arc<MjModel>>,
    pub(crate) frame_skip: usize,
    /// `qpos`/`qvel` of a fresh `MjData` (Gymnasium's `init_qpos`/`init_qvel`).
    pub(crate) init_qpos: Vec<f64>,
    pub(crate) init_qvel: Vec<f64>,
}

impl Sim {
    pub(crate) fn new(model: Arc<MjModel>, frame_skip: usize) -> Self {
        let data = MjData::new(model);
        Sim {
            init_qpos: data.qpos().to_vec(),
            init_qvel: data.qvel().to_vec(),
            data,
            frame_skip,
        }
    }

    pub(crate) fn model(&self) -> &MjModel {
        self.data.model()
    }

    pub(crate) fn nq(&self) -> usize {
        self.model().ffi().nq as usize
    }

    pub(crate) fn nv(&self) -> usize {
        self.model().ffi().nv as usize
    }

    pub(crate) fn nu(&self) -> usize {
        self.model().ffi().nu as usize
    }

    /// Seconds per env step: `timestep * frame_skip`.
    pub(crate) fn dt(&self) -> f64 {
        self.model().opt().timestep * self.frame_skip as f64
    }

    pub(crate) fn qpos(&self) -> &[f64] {
        self.data.qpos()
    }

    pub(crate) fn qvel(&self) -> &[f64] {
        self.data.qvel()
    }

    /// `mj_resetData`, as `MujocoEnv.reset` does before `reset_model`.
    pub(crate) fn reset(&mut self) {
        self.data.reset();
    }

    /// `MujocoEnv.set_state`: copy `qpos`/`qvel` in, then `mj_forward`.
    pub(crate) fn set_state(&mut self, qpos: &[f64], qvel: &[f64]) {
        self.data.qpos_mut().copy_from_slice(qpos);
        self.data.qvel_mut().copy_from_slice(qvel);
        self.data.forward();
    }

    /// `MujocoEnv.do_simulation`: set `ctrl` (float32 actions widen exactly), `mj_step`
    /// `frame_skip` times, then `mj_rnePostConstraint` (for `cfrc_ext`).
    pub(crate) fn do_simulation(&mut self, ctrl: impl IntoIterator<Item = f64>) {
        for (c, a) in self.data.ctrl_mut().iter_mut().zip(ctrl) {
            *c = a;
        }
        for _ in 0..self.frame_skip {
            self.data.step();
        }
        self.data.rne_post_constraint();
    }

    /// Id of the body named `name`.
    pub(crate) fn body_id(&self, env_id: &str, name: &str) -> Result<usize, EnvError> {
        self.model()
            .name_to_id(MjtObjBase::mjOBJ_BODY, name)
            .ok_or_else(|| EnvError::Simulator {
                env_id: env_id.to_string(),
                reason: format!("the model has no body `{name}`"),
            })
    }

    /// `data.body(id).xpos`.
    pub(crate) fn body_xpos(&self, body: usize) -> [f64; 3] {
        self.data.xpos()[body]
    }

    /// Whether every element of `qpos` and `qvel` is finite.
    pub(crate) fn state_is_finite(&self) -> bool {
        self.qpos().iter().chain(self.qvel()).all(|x| x.is_finite())
    }
}

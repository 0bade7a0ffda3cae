//! `MujocoEnv`: the `Env` every MuJoCo task runs in — Gymnasium's `MujocoEnv` base class.

use crate::obs::{ObsWriter, read_f32s};
use crate::render::{self, RenderSetup, Renderer};
use crate::sim::{ModelCache, Sim};
use crate::tasks::{EnvEntry, Task};
use envhub_core::{
    DType, Env, EnvConfig, EnvError, Info, NumpyRng, ResetOptions, Space, Transition,
};

/// `extra` keys every task of the `mujoco` adapter takes, besides its own.
const COMMON_OPTIONS: &[&str] = &["xml_file", "frame_skip"];

/// The reset options: a state to start from instead of the random one.
const RESET_OPTIONS: &[&str] = &["qpos", "qvel"];

/// One MuJoCo env: a simulator, a task (observation, reward, termination, reset
/// distribution), NumPy's generator for the reset noise, and an optional renderer.
///
/// Beyond Gymnasium's contract, `reset` takes `{"qpos": [...], "qvel": [...]}` options: the
/// episode starts from that state (each key optional; the other part is drawn as usual, and the
/// generator advances as in a plain reset), which demonstrations and curricula need.
pub struct MujocoEnv {
    env_id: String,
    sim: Sim,
    task: Box<dyn Task>,
    observation_space: Space,
    action_space: Space,
    options: Vec<String>,
    rng: Option<NumpyRng>,
    qpos: Vec<f64>,
    qvel: Vec<f64>,
    action: Vec<f32>,
    render: Option<RenderSetup>,
    renderer: Option<Renderer>,
    started: bool,
}

impl MujocoEnv {
    /// A task of the `mujoco` adapter, configured from `config`.
    pub(crate) fn new(
        entry: &EnvEntry,
        config: &EnvConfig,
        models: &ModelCache,
    ) -> Result<Self, EnvError> {
        let options: Vec<&str> = entry
            .options
            .iter()
            .chain(COMMON_OPTIONS)
            .chain(render::OPTIONS)
            .copied()
            .collect();
        let keys = config.extra_keys(entry.id, &options)?;
        let render =
            RenderSetup::from_config(entry.id, config, &keys, entry.default_camera_config)?;
        let frame_skip = keys.u64("frame_skip", entry.frame_skip)?;
        if frame_skip == 0 {
            return Err(keys.error("frame_skip", "must be at least 1"));
        }
        let path = match (&config.asset_path, keys.str("xml_file")?) {
            (Some(path), _) => path.clone(),
            (None, Some(file)) => crate::assets::model_path(file)?,
            (None, None) => crate::assets::model_path(entry.xml_file)?,
        };
        let model = models.load(&path, render.as_ref().map(|r| (r.width, r.height)))?;
        let sim = Sim::new(model, frame_skip as usize);
        let task = (entry.make)(&keys, &sim)?;
        Self::from_parts(entry.id, sim, task, &options, render)
    }

    /// An env from its parts (the `custom_mjcf` adapter builds its own).
    pub(crate) fn from_parts(
        env_id: &str,
        sim: Sim,
        task: Box<dyn Task>,
        options: &[&str],
        render: Option<RenderSetup>,
    ) -> Result<Self, EnvError> {
        let mut count = ObsWriter::counting();
        task.write_obs(&sim, &mut count);
        let n = count.len();
        let observation_space = Space::Box {
            dtype: DType::Float64,
            shape: vec![n],
            low: vec![f64::NEG_INFINITY; n],
            high: vec![f64::INFINITY; n],
        };
        let action_space = task.action_space(&sim);
        Ok(MujocoEnv {
            env_id: env_id.to_string(),
            qpos: vec![0.0; sim.nq()],
            qvel: vec![0.0; sim.nv()],
            action: Vec::with_capacity(sim.nu()),
            sim,
            task,
            observation_space,
            action_space,
            options: options.iter().map(|o| o.to_string()).collect(),
            rng: None,
            render,
            renderer: None,
            started: false,
        })
    }

    /// The `extra` keys this env takes.
    pub fn options(&self) -> Vec<String> {
        self.options.clone()
    }

    /// The generalized positions (`data.qpos`).
    pub fn qpos(&self) -> &[f64] {
        self.sim.qpos()
    }

    /// The generalized velocities (`data.qvel`).
    pub fn qvel(&self) -> &[f64] {
        self.sim.qvel()
    }

    /// Seconds of simulated time per step (`timestep * frame_skip`).
    pub fn dt(&self) -> f64 {
        self.sim.dt()
    }

    /// Replaces `qpos` and `qvel` (Gymnasium's `set_state`), then recomputes the derived
    /// quantities; the next `step` starts from there.
    pub fn set_state(&mut self, qpos: &[f64], qvel: &[f64]) -> Result<(), EnvError> {
        self.check_len("qpos", qpos.len(), self.sim.nq())?;
        self.check_len("qvel", qvel.len(), self.sim.nv())?;
        self.sim.set_state(qpos, qvel);
        self.started = true;
        Ok(())
    }

    fn check_len(&self, what: &str, got: usize, want: usize) -> Result<(), EnvError> {
        if got == want {
            Ok(())
        } else {
            Err(self.invalid_reset(format!(
                "`{what}` needs {want} values for this model, got {got}"
            )))
        }
    }

    fn invalid_reset(&self, reason: String) -> EnvError {
        EnvError::InvalidReset {
            env_id: self.env_id.clone(),
            reason,
        }
    }

    /// Reads `qpos`/`qvel` from the reset options into `out`.
    fn state_option(
        &self,
        options: &ResetOptions,
        key: &str,
        out: &mut [f64],
    ) -> Result<(), EnvError> {
        let Some(value) = options.get(key) else {
            return Ok(());
        };
        let list = value
            .as_array()
            .ok_or_else(|| self.invalid_reset(format!("`{key}` must be a list of numbers")))?;
        self.check_len(key, list.len(), out.len())?;
        for (slot, v) in out.iter_mut().zip(list) {
            *slot = v.as_f64().ok_or_else(|| {
                self.invalid_reset(format!("`{key}` must be a list of numbers, found `{v}`"))
            })?;
        }
        Ok(())
    }
}

impl Env for MujocoEnv {
    fn observation_space(&self) -> &Space {
        &self.observation_space
    }

    fn action_space(&self) -> &Space {
        &self.action_space
    }

    fn reset(
        &mut self,
        seed: Option<u64>,
        options: &ResetOptions,
        obs: &mut [u8],
        info: &mut Info,
    ) -> Result<(), EnvError> {
        if let Some(key) = options
            .keys()
            .find(|k| !RESET_OPTIONS.contains(&k.as_str()))
        {
            let hint = envhub_core::closest(key, RESET_OPTIONS.iter().copied(), 1)
                .first()
                .map(|c| format!("; did you mean `{c}`?"))
                .unwrap_or_default();
            return Err(self.invalid_reset(format!(
                "unknown option `{key}`{hint}\nhint: valid reset options are `qpos`, `qvel`"
            )));
        }
        let rng = NumpyRng::reseed(&mut self.rng, seed);
        self.sim.reset();
        self.task
            .reset_model(&self.sim, rng, &mut self.qpos, &mut self.qvel);
        let (mut qpos, mut qvel) = (
            std::mem::take(&mut self.qpos),
            std::mem::take(&mut self.qvel),
        );
        let given = self
            .state_option(options, "qpos", &mut qpos)
            .and_then(|()| self.state_option(options, "qvel", &mut qvel));
        self.sim.set_state(&qpos, &qvel);
        (self.qpos, self.qvel) = (qpos, qvel);
        given?;
        let mut w = ObsWriter::new(obs);
        self.task.write_obs(&self.sim, &mut w);
        w.finish();
        self.task.reset_info(&self.sim, info);
        self.started = true;
        Ok(())
    }

    fn step(
        &mut self,
        action: &[u8],
        obs: &mut [u8],
        info: &mut Info,
    ) -> Result<Transition, EnvError> {
        if !self.started {
            return Err(EnvError::Simulator {
                env_id: self.env_id.clone(),
                reason: "`step` called before `reset`\nhint: call `reset` first".into(),
            });
        }
        read_f32s(action, &mut self.action);
        let (reward, terminated) = self.task.step(&mut self.sim, &self.action, info);
        let mut w = ObsWriter::new(obs);
        self.task.write_obs(&self.sim, &mut w);
        w.finish();
        Ok(Transition {
            reward,
            terminated,
            truncated: false,
        })
    }

    fn render(&mut self) -> Result<Option<(usize, usize, Vec<u8>)>, EnvError> {
        let Some(setup) = &self.render else {
            return Ok(None);
        };
        if self.renderer.is_none() {
            self.renderer = Some(Renderer::new(&self.env_id, setup, &self.sim.data)?);
        }
        let renderer = self.renderer.as_mut().expect("created above");
        renderer.render(&self.env_id, &mut self.sim.data).map(Some)
    }

    /// Gymnasium's `metadata["render_fps"]`: `int(np.round(1.0 / dt))`.
    fn render_fps(&self) -> Option<f64> {
        Some((1.0 / self.sim.dt()).round_ties_even())
    }

    fn close(&mut self) {
        self.renderer = None;
    }
}

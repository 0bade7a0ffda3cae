//! A worker's envs as one batch: reset, step with autoreset, results written into the blocks
//! of a response. Used by the worker loop and, without any IPC, by in-process benchmarks.

use crate::ServedBatch;
use crate::layout::{ResponseBlocksMut, env_flag};
use envhub_core::{AutoresetMode, Env, EnvError, Info, InfoValue, ResetOptions};

/// The envs one worker hosts.
pub struct EnvBatch {
    envs: Vec<Box<dyn Env>>,
    mode: AutoresetMode,
    obs_bytes: usize,
    act_bytes: usize,
    /// next_step mode: the env finished last step and resets on this one.
    pending_reset: Vec<bool>,
    infos: Vec<Info>,
    /// Envs that failed in the last call, with the error.
    failures: Vec<(usize, String)>,
}

impl EnvBatch {
    /// A batch of envs (all with the same spaces) under an autoreset mode.
    pub fn new(envs: Vec<Box<dyn Env>>, mode: AutoresetMode) -> EnvBatch {
        let obs_bytes = envs.first().map_or(0, |e| e.observation_space().byte_len());
        let act_bytes = envs.first().map_or(0, |e| e.action_space().byte_len());
        let n = envs.len();
        EnvBatch {
            envs,
            mode,
            obs_bytes,
            act_bytes,
            pending_reset: vec![false; n],
            infos: vec![Info::default(); n],
            failures: Vec::new(),
        }
    }
}

impl EnvBatch {
    /// Records env `i`'s failure and leaves it neutral rows; the other envs go on.
    fn failed(&mut self, i: usize, e: EnvError, out: &mut ResponseBlocksMut<'_>) {
        self.failures.push((i, e.to_string()));
        self.infos[i].clear();
        self.pending_reset[i] = false;
        out.rewards[i] = 0.0;
        out.terminated[i] = 0;
        out.truncated[i] = 0;
        out.final_mask[i] = 0;
    }
}

/// The serve loop's view of the batch (the worker loop and in-process runs alike). One env's
/// error does not stop the others: they are reset or stepped, and the failed env is reported
/// (see [`ServedBatch::take_failures`]) so the client can tell its user which env to reset.
impl ServedBatch for EnvBatch {
    fn len(&self) -> usize {
        self.envs.len()
    }

    /// Resets the envs whose flag has [`env_flag::SELECTED`], seeding those with
    /// [`env_flag::SEEDED`]. Returns the info section.
    fn reset(
        &mut self,
        flags: &[u8],
        seeds: &[u64],
        options: &ResetOptions,
        out: &mut ResponseBlocksMut<'_>,
    ) -> Result<Vec<u8>, EnvError> {
        let ob = self.obs_bytes;
        for i in 0..self.envs.len() {
            let selected = flags[i] & env_flag::SELECTED != 0;
            if selected {
                let seed = (flags[i] & env_flag::SEEDED != 0).then_some(seeds[i]);
                self.infos[i].clear();
                let reset = self.envs[i].reset(
                    seed,
                    options,
                    &mut out.obs[i * ob..(i + 1) * ob],
                    &mut self.infos[i],
                );
                if let Err(e) = reset {
                    self.failed(i, e, out);
                    continue;
                }
                self.pending_reset[i] = false;
            } else {
                self.infos[i].clear();
            }
            out.rewards[i] = 0.0;
            out.terminated[i] = 0;
            out.truncated[i] = 0;
            out.final_mask[i] = 0;
        }
        Ok(info_section(&self.infos))
    }

    /// Steps the selected envs, applying the autoreset mode. Unselected envs keep their
    /// slots untouched except for the flags, which are cleared.
    fn step(
        &mut self,
        flags: &[u8],
        actions: &[u8],
        out: &mut ResponseBlocksMut<'_>,
    ) -> Result<Vec<u8>, EnvError> {
        let (ob, ab) = (self.obs_bytes, self.act_bytes);
        let no_options = ResetOptions::new();
        for i in 0..self.envs.len() {
            out.final_mask[i] = 0;
            self.infos[i].clear();
            if flags[i] & env_flag::SELECTED == 0 {
                out.rewards[i] = 0.0;
                out.terminated[i] = 0;
                out.truncated[i] = 0;
                continue;
            }
            let obs = &mut out.obs[i * ob..(i + 1) * ob];
            if self.pending_reset[i] {
                // next_step: this step only resets, the action is ignored (Gymnasium 1.x).
                if let Err(e) = self.envs[i].reset(None, &no_options, obs, &mut self.infos[i]) {
                    self.failed(i, e, out);
                    continue;
                }
                self.pending_reset[i] = false;
                out.rewards[i] = 0.0;
                out.terminated[i] = 0;
                out.truncated[i] = 0;
                continue;
            }
            let t = match self.envs[i].step(&actions[i * ab..(i + 1) * ab], obs, &mut self.infos[i])
            {
                Ok(t) => t,
                Err(e) => {
                    self.failed(i, e, out);
                    continue;
                }
            };
            out.rewards[i] = t.reward;
            out.terminated[i] = t.terminated as u8;
            out.truncated[i] = t.truncated as u8;
            if t.terminated || t.truncated {
                match self.mode {
                    AutoresetMode::NextStep => self.pending_reset[i] = true,
                    AutoresetMode::SameStep => {
                        out.final_obs[i * ob..(i + 1) * ob].copy_from_slice(obs);
                        out.final_mask[i] = 1;
                        let final_info = std::mem::take(&mut self.infos[i]);
                        if let Err(e) =
                            self.envs[i].reset(None, &no_options, obs, &mut self.infos[i])
                        {
                            self.failed(i, e, out);
                            continue;
                        }
                        if !final_info.is_empty() {
                            self.infos[i]
                                .insert("final_info", InfoValue::Text(info_object(&final_info)));
                        }
                    }
                    AutoresetMode::Disabled => {}
                }
            }
        }
        Ok(info_section(&self.infos))
    }

    /// Renders the selected envs: their frames in order, as [`frames_section`] lays them out.
    fn render(&mut self, flags: &[u8]) -> Result<Vec<u8>, EnvError> {
        let mut frames = Vec::new();
        for (env, &flag) in self.envs.iter_mut().zip(flags) {
            if flag & env_flag::SELECTED != 0 {
                frames.push(env.render()?);
            }
        }
        Ok(frames_section(frames))
    }

    /// Closes every env.
    fn close(&mut self) {
        for env in &mut self.envs {
            env.close();
        }
    }

    fn take_failures(&mut self) -> Vec<(usize, String)> {
        std::mem::take(&mut self.failures)
    }
}

/// The answer to a render: for each frame a `u32` height, a `u32` width (both 0 for `None`,
/// nothing rendered) and `height × width × 3` RGB bytes, all little-endian.
pub fn frames_section(frames: impl IntoIterator<Item = Option<Frame>>) -> Vec<u8> {
    let mut out = Vec::new();
    for frame in frames {
        match frame {
            Some((h, w, rgb)) => {
                out.extend_from_slice(&(h as u32).to_le_bytes());
                out.extend_from_slice(&(w as u32).to_le_bytes());
                out.extend_from_slice(&rgb);
            }
            None => out.extend_from_slice(&[0; 8]),
        }
    }
    out
}

/// One rendered frame: height, width and `height × width × 3` RGB bytes.
pub type Frame = (usize, usize, Vec<u8>);

/// `[{...}, {...}]` with one object per env, or nothing when no env reported info.
fn info_section(infos: &[Info]) -> Vec<u8> {
    if infos.iter().all(Info::is_empty) {
        return Vec::new();
    }
    let mut out = String::from("[");
    for (i, info) in infos.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        out.push_str(&info_object(info));
    }
    out.push(']');
    out.into_bytes()
}

fn info_object(info: &Info) -> String {
    let map: serde_json::Map<String, serde_json::Value> = info
        .iter()
        .map(|(k, v)| {
            let value = match v {
                // A nested info (same_step `final_info`) travels as JSON text; unwrap it.
                InfoValue::Text(t) if k == "final_info" => {
                    serde_json::from_str(t).unwrap_or_default()
                }
                other => serde_json::to_value(other).unwrap_or_default(),
            };
            (k.to_string(), value)
        })
        .collect();
    serde_json::Value::Object(map).to_string()
}

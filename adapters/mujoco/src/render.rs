//! `render_mode="rgb_array"`: MuJoCo's own offscreen renderer on an EGL context, set up the way
//! Gymnasium's `MujocoRenderer` sets it up, so a frame is Gymnasium's frame of the same state.
//!
//! Without a GPU, Mesa's software EGL (`libegl1 libegl-mesa0 libgl1-mesa-dri`, which `make`
//! installs) draws the frames on the CPU. The context is created at the first `render`, so
//! envs that never render cost nothing, and a machine where EGL cannot work gets an error that
//! says why at that point.
//!
//! The camera follows `gymnasium/envs/mujoco/mujoco_rendering.py`: with neither `camera_id`
//! nor `camera_name`, the free camera (even where the model has a `track` camera), made by
//! `mjv_defaultCamera`, then aimed at the per-axis median of the geoms' positions at the first
//! render from the model's extent away (`OffScreenViewer._init_camera`), then given the task's
//! `default_camera_config` (`MujocoRenderer._set_cam_config`). Gymnasium sets the camera type
//! last, so a `trackbodyid` in a config never makes the free camera track a body; the same
//! holds here.

use crate::modes::RGB_ARRAY;
use envhub_core::{EnvConfig, EnvError, ExtraKeys};
use mujoco_rs::prelude::*;
use mujoco_rs::renderer::MjRenderer;
use serde_json::Value;
use std::sync::Arc;

/// Gymnasium's `DEFAULT_SIZE`.
const DEFAULT_SIZE: u64 = 480;

/// Gymnasium's `max_geom`: room for this many geoms in the scene.
const MAX_GEOM: u32 = 1000;

/// The `extra` keys rendering takes (Gymnasium's `MujocoEnv` kwargs).
pub(crate) const OPTIONS: &[&str] = &[
    "width",
    "height",
    "camera_id",
    "camera_name",
    "default_camera_config",
];

/// Gymnasium's `default_camera_config`: `MjvCamera` fields set after the free camera is aimed
/// at the model (each `None` keeps that). A task declares its default as a
/// `DEFAULT_CAMERA_CONFIG` const; `extra["default_camera_config"]` replaces it as a whole,
/// as the kwarg does in Gymnasium.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct CameraConfig {
    /// `type` (`mjtCamera`); Gymnasium sets the type again when it renders, so it has no effect.
    pub(crate) camera_type: Option<i32>,
    pub(crate) fixedcamid: Option<i32>,
    /// Has no effect on the free camera (see the module docs); kept as Gymnasium's tasks give it.
    pub(crate) trackbodyid: Option<i32>,
    pub(crate) lookat: Option<[f64; 3]>,
    pub(crate) distance: Option<f64>,
    pub(crate) azimuth: Option<f64>,
    pub(crate) elevation: Option<f64>,
    pub(crate) orthographic: Option<i32>,
}

/// The keys of a `default_camera_config` (the fields of `MjvCamera`).
const CAMERA_KEYS: &[&str] = &[
    "type",
    "fixedcamid",
    "trackbodyid",
    "lookat",
    "distance",
    "azimuth",
    "elevation",
    "orthographic",
];

impl CameraConfig {
    /// No config (Gymnasium's `default_camera_config=None`).
    pub(crate) const NONE: CameraConfig = CameraConfig {
        camera_type: None,
        fixedcamid: None,
        trackbodyid: None,
        lookat: None,
        distance: None,
        azimuth: None,
        elevation: None,
        orthographic: None,
    };

    /// `extra["default_camera_config"]`: a mapping of `MjvCamera` fields, or `null` for none.
    fn from_json(keys: &ExtraKeys, value: &Value) -> Result<CameraConfig, EnvError> {
        const KEY: &str = "default_camera_config";
        if value.is_null() {
            return Ok(CameraConfig::NONE);
        }
        let map = value.as_object().ok_or_else(|| {
            keys.error(
                KEY,
                format!("expected a mapping of camera fields, got `{value}`"),
            )
        })?;
        let mut config = CameraConfig::NONE;
        for (field, v) in map {
            let bad = |what: &str| keys.error(KEY, format!("`{field}` must be {what}, got `{v}`"));
            let int = || {
                v.as_i64()
                    .and_then(|i| i32::try_from(i).ok())
                    .ok_or_else(|| bad("an integer"))
            };
            let num = || {
                v.as_f64()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| bad("a finite number"))
            };
            match field.as_str() {
                "type" => config.camera_type = Some(int()?),
                "fixedcamid" => config.fixedcamid = Some(int()?),
                "trackbodyid" => config.trackbodyid = Some(int()?),
                "orthographic" => config.orthographic = Some(int()?),
                "distance" => config.distance = Some(num()?),
                "azimuth" => config.azimuth = Some(num()?),
                "elevation" => config.elevation = Some(num()?),
                "lookat" => {
                    let xyz = v
                        .as_array()
                        .and_then(|a| a.iter().map(Value::as_f64).collect::<Option<Vec<f64>>>());
                    let Some(&[x, y, z]) = xyz.as_deref() else {
                        return Err(bad("a list of 3 numbers"));
                    };
                    config.lookat = Some([x, y, z]);
                }
                other => {
                    let hint = envhub_core::closest(other, CAMERA_KEYS.iter().copied(), 1)
                        .first()
                        .map(|c| format!("; did you mean `{c}`?"))
                        .unwrap_or_default();
                    return Err(keys.error(
                        KEY,
                        format!(
                            "unknown camera field `{other}`{hint}\nhint: the fields are `{}`",
                            CAMERA_KEYS.join("`, `")
                        ),
                    ));
                }
            }
        }
        Ok(config)
    }

    /// `MujocoRenderer._set_cam_config`: sets the given fields.
    fn apply(&self, cam: &mut MjvCamera) {
        let CameraConfig {
            camera_type,
            fixedcamid,
            trackbodyid,
            lookat,
            distance,
            azimuth,
            elevation,
            orthographic,
        } = *self;
        if let Some(v) = camera_type {
            cam.type_ = v;
        }
        if let Some(v) = fixedcamid {
            cam.fixedcamid = v;
        }
        if let Some(v) = trackbodyid {
            cam.trackbodyid = v;
        }
        if let Some(v) = lookat {
            cam.lookat = v;
        }
        if let Some(v) = distance {
            cam.distance = v;
        }
        if let Some(v) = azimuth {
            cam.azimuth = v;
        }
        if let Some(v) = elevation {
            cam.elevation = v;
        }
        if let Some(v) = orthographic {
            cam.orthographic = v;
        }
    }
}

/// What to draw: image size and camera.
#[derive(Clone, Debug)]
pub(crate) struct RenderSetup {
    pub(crate) width: u32,
    pub(crate) height: u32,
    /// `-1` is the free camera, as in Gymnasium.
    camera_id: Option<i64>,
    camera_name: Option<String>,
    camera_config: CameraConfig,
}

impl RenderSetup {
    /// Reads `render_mode` and the render options; `None` when the env does not render.
    /// `default_camera` is the task's `DEFAULT_CAMERA_CONFIG`.
    pub(crate) fn from_config(
        env_id: &str,
        config: &EnvConfig,
        keys: &ExtraKeys,
        default_camera: CameraConfig,
    ) -> Result<Option<RenderSetup>, EnvError> {
        let width = keys.u64("width", DEFAULT_SIZE)?;
        let height = keys.u64("height", DEFAULT_SIZE)?;
        let camera_id = match keys.value("camera_id") {
            None | Some(Value::Null) => None,
            Some(v) => Some(v.as_i64().filter(|id| *id >= -1).ok_or_else(|| {
                keys.error(
                    "camera_id",
                    format!("expected a camera number, or -1 for the free camera, got `{v}`"),
                )
            })?),
        };
        let camera_name = match keys.value("camera_name") {
            None | Some(Value::Null) => None,
            Some(_) => keys.str("camera_name")?.map(str::to_string),
        };
        if camera_id.is_some() && camera_name.is_some() {
            return Err(keys.error(
                "camera_name",
                "give `camera_id` or `camera_name`, not both (as Gymnasium requires)",
            ));
        }
        let camera_config = match keys.value("default_camera_config") {
            Some(v) => CameraConfig::from_json(keys, v)?,
            None => default_camera,
        };
        for (key, v) in [("width", width), ("height", height)] {
            if v == 0 || v > 16384 {
                return Err(keys.error(key, format!("must be 1 to 16384 pixels, got {v}")));
            }
        }
        match config.render_mode.as_deref() {
            None => Ok(None),
            Some(RGB_ARRAY) => Ok(Some(RenderSetup {
                width: width as u32,
                height: height as u32,
                camera_id,
                camera_name,
                camera_config,
            })),
            Some(mode) => Err(EnvError::RenderMode {
                env_id: env_id.to_string(),
                mode: mode.to_string(),
                supported: vec![RGB_ARRAY.into()],
            }),
        }
    }

    /// The fixed camera to draw from (`None`: the free camera). Unlike Gymnasium, which falls
    /// back to the free camera, a `camera_name` the model lacks is an error.
    fn fixed_camera(&self, env_id: &str, model: &MjModel) -> Result<Option<i32>, EnvError> {
        let ncam = model.ffi().ncam;
        match (&self.camera_name, self.camera_id) {
            (Some(name), _) => model
                .name_to_id(MjtObjBase::mjOBJ_CAMERA, name)
                .map(|id| Some(id as i32))
                .ok_or_else(|| EnvError::InvalidOption {
                    env_id: env_id.to_string(),
                    key: "camera_name".into(),
                    reason: format!("the model has no camera `{name}`{}", cameras(model)),
                }),
            (None, Some(id)) if id >= ncam => Err(EnvError::InvalidOption {
                env_id: env_id.to_string(),
                key: "camera_id".into(),
                reason: format!(
                    "the model has {ncam} cameras{}; -1 is the free camera",
                    cameras(model)
                ),
            }),
            (None, Some(-1) | None) => Ok(None),
            (None, Some(id)) => Ok(Some(id as i32)),
        }
    }

    /// The camera as Gymnasium sets it up at the first render (see the module docs).
    fn camera(&self, env_id: &str, data: &MjData<Arc<MjModel>>) -> Result<MjvCamera, EnvError> {
        let model = data.model();
        let fixed = self.fixed_camera(env_id, model)?;
        // `OffScreenViewer._init_camera`, on `mjv_defaultCamera`'s camera.
        let xpos = data.geom_xpos();
        let mut cam = MjvCamera {
            type_: MjtCamera::mjCAMERA_FREE as i32,
            fixedcamid: -1,
            lookat: [0, 1, 2].map(|axis| median(xpos.iter().map(|p| p[axis]).collect())),
            distance: model.stat().extent,
            ..MjvCamera::default()
        };
        // `MujocoRenderer._set_cam_config`.
        self.camera_config.apply(&mut cam);
        // `OffScreenViewer.render(camera_id=...)`.
        match fixed {
            Some(id) => {
                cam.type_ = MjtCamera::mjCAMERA_FIXED as i32;
                cam.fixedcamid = id;
            }
            None => {
                cam.type_ = MjtCamera::mjCAMERA_FREE as i32;
                cam.fixedcamid = -1;
            }
        }
        Ok(cam)
    }
}

/// `np.median`: the middle value, or the mean of the two middle ones (0 for none).
fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    match n {
        0 => 0.0,
        _ if n % 2 == 1 => values[n / 2],
        _ => (values[n / 2 - 1] + values[n / 2]) / 2.0,
    }
}

fn cameras(model: &MjModel) -> String {
    let names: Vec<String> = (0..model.ffi().ncam as usize)
        .map(|i| {
            let name = model.id_to_name(MjtObjBase::mjOBJ_CAMERA, i).unwrap_or("");
            format!("{i} `{name}`")
        })
        .collect();
    if names.is_empty() {
        String::new()
    } else {
        format!("; it has {}", names.join(", "))
    }
}

/// An offscreen renderer bound to one model.
pub(crate) struct Renderer {
    inner: MjRenderer,
    width: usize,
    height: usize,
}

// SAFETY: the renderer owns its EGL context and surface and is only used through `&mut self`,
// so never from two threads at once. Every draw first makes the context current on the calling
// thread (mujoco-rs), and EGL refuses, with an error and no GL call, to make it current on a
// thread while it is current on another — a renderer moved between threads fails to render,
// it does not race. `Env` must be `Send` for worker threads (`envhub-worker inproc`), which
// create, step and render each env on one thread.
unsafe impl Send for Renderer {}

impl Renderer {
    /// A renderer whose camera is aimed at the current state of `data` (as Gymnasium's is at
    /// its first render).
    pub(crate) fn new(
        env_id: &str,
        setup: &RenderSetup,
        data: &MjData<Arc<MjModel>>,
    ) -> Result<Self, EnvError> {
        let model = data.model();
        let camera = setup.camera(env_id, data)?;
        let ngeom = u32::try_from(model.ffi().ngeom).unwrap_or(0);
        let inner = MjRenderer::builder()
            .width(setup.width)
            .height(setup.height)
            .camera(camera)
            .num_visual_internal_geom(MAX_GEOM.saturating_sub(ngeom))
            .build(model)
            .map_err(|e| EnvError::Simulator {
                env_id: env_id.to_string(),
                reason: format!(
                    "cannot render offscreen: {}\nhint: rendering needs EGL; without a GPU, \
                     Mesa's software EGL: `apt-get install libegl1 libegl-mesa0 \
                     libgl1-mesa-dri` (`make setup` does it)",
                    chain(&e)
                ),
            })?;
        Ok(Renderer {
            inner,
            width: setup.width as usize,
            height: setup.height as usize,
        })
    }

    /// Draws the current state: `(height, width, rgb)`, row 0 at the top.
    pub(crate) fn render(
        &mut self,
        env_id: &str,
        data: &mut MjData<Arc<MjModel>>,
    ) -> Result<(usize, usize, Vec<u8>), EnvError> {
        let failed = |e: &dyn std::error::Error| EnvError::Simulator {
            env_id: env_id.to_string(),
            reason: format!("rendering failed: {}", chain(e)),
        };
        self.inner.sync_data(data).map_err(|e| failed(&e))?;
        self.inner.render().map_err(|e| failed(&e))?;
        let rgb = self.inner.rgb_flat().unwrap_or_default().to_vec();
        Ok((self.height, self.width, rgb))
    }
}

/// An error and its causes, `: `-separated.
fn chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        text.push_str(&format!(": {c}"));
        cause = c.source();
    }
    text
}

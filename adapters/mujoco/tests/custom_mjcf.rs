//! The `custom_mjcf` adapter: the registry's example walker, URDF, configured rewards, and the
//! errors for missing and broken model files.

use envhub_core::{Env, EnvAdapter, EnvConfig, Info, InfoValue, ResetOptions};
use envhub_mujoco::CustomMjcf;
use serde_json::json;
use std::path::{Path, PathBuf};

/// The registry's example model (`custom-mjcf-planar-walker`).
pub(crate) fn planar_walker() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/assets/planar_walker.xml")
}

/// A file in a fresh temporary folder for this test.
fn temp_file(test: &str, name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("envhub-mujoco-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

fn config(path: PathBuf) -> EnvConfig {
    EnvConfig {
        asset_path: Some(path),
        ..EnvConfig::default()
    }
}

#[test]
fn planar_walker_steps_with_a_configured_reward() {
    let adapter = CustomMjcf::default();
    let mut cfg = config(planar_walker());
    let spec = adapter.spec("PlanarWalker-v0", &cfg).unwrap();
    // 7 joints' positions (3 root + 4 leg) and velocities; 4 motors.
    assert_eq!(spec.observation_space.shape(), Some(vec![14]));
    assert_eq!(spec.action_space.to_string(), "Box(-1, 1, [4], float32)");

    // Reward 0 unless configured.
    let mut env = adapter.make("PlanarWalker-v0", &cfg).unwrap();
    let mut obs = vec![0u8; env.observation_space().byte_len()];
    let mut info = Info::default();
    env.reset(Some(0), &ResetOptions::new(), &mut obs, &mut info)
        .unwrap();
    let action: Vec<u8> = [1.0f32, -1.0, 0.5, -0.5]
        .iter()
        .flat_map(|a| a.to_le_bytes())
        .collect();
    let t = env.step(&action, &mut obs, &mut info).unwrap();
    assert_eq!(t.reward, 0.0);
    assert!(!t.terminated);

    cfg.extra = [
        ("forward_reward_body".to_string(), json!("torso")),
        ("ctrl_cost_weight".to_string(), json!(0.1)),
        ("frame_skip".to_string(), json!(4)),
        ("healthy_z_range".to_string(), json!([0.5, 2.0])),
        ("healthy_reward".to_string(), json!(1.0)),
    ]
    .into();
    let mut env = CustomMjcf::default()
        .make_mujoco("PlanarWalker-v0", &cfg)
        .unwrap();
    assert!((env.dt() - 0.02).abs() < 1e-12);
    env.reset(Some(0), &ResetOptions::new(), &mut obs, &mut info)
        .unwrap();
    let t = env.step(&action, &mut obs, &mut info).unwrap();
    let Some(InfoValue::Float(vx)) = info.get("x_velocity").cloned() else {
        panic!("no x_velocity in {info:?}");
    };
    let ctrl = 0.1 * (1.0 + 1.0 + 0.25 + 0.25);
    assert!(
        (t.reward - (vx + 1.0 - ctrl)).abs() < 1e-9,
        "{t:?} {info:?}"
    );
    // Falling over ends the episode.
    let mut fallen = false;
    for _ in 0..500 {
        if env.step(&action, &mut obs, &mut info).unwrap().terminated {
            fallen = true;
            break;
        }
    }
    assert!(fallen, "the walker never left its healthy height range");
}

#[test]
fn loads_urdf() {
    let urdf = r#"<robot name="pendulum">
  <link name="base">
    <inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
  </link>
  <link name="arm">
    <inertial><origin xyz="0 0 -0.5"/><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><origin xyz="0 0 -0.25"/><geometry><cylinder radius="0.02" length="0.5"/></geometry></visual>
  </link>
  <joint name="hinge" type="continuous">
    <parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
  </joint>
</robot>
"#;
    let path = temp_file("urdf", "pendulum.urdf", urdf);
    let mut env = CustomMjcf::default()
        .make_mujoco("Pendulum-urdf", &config(path))
        .unwrap();
    assert_eq!(env.observation_space().shape(), Some(vec![2]));
    assert_eq!(env.action_space().shape(), Some(vec![0]));
    let mut obs = vec![0u8; 16];
    let options: ResetOptions = [("qpos".to_string(), json!([0.5]))].into();
    env.reset(Some(0), &options, &mut obs, &mut Info::default())
        .unwrap();
    let t = env.step(&[], &mut obs, &mut Info::default()).unwrap();
    assert!(!t.terminated);
    assert!(env.qvel()[0] != 0.0, "gravity swings the arm");
}

#[test]
fn missing_or_broken_files_name_the_path_and_mujocos_error() {
    let adapter = CustomMjcf::default();
    let missing = PathBuf::from("/nonexistent/robot.xml");
    let err = adapter
        .make("X-v0", &config(missing))
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("cannot load asset `/nonexistent/robot.xml`: no such file"),
        "{err}"
    );

    let broken = "<mujoco>\n  <worldbody>\n    <body name=\"a\">\n      <geom type=\"sphere\" size=\"0.1\"/>\n  </worldbody>\n</mujoco>\n";
    let path = temp_file("broken", "broken.xml", broken);
    let err = adapter
        .make("X-v0", &config(path.clone()))
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains(&path.display().to_string()), "{err}");
    assert!(
        err.contains("MuJoCo: XML parse error") && err.contains("Line number=3"),
        "{err}"
    );

    let unknown = "<mujoco>\n  <worldbody>\n    <bodyy/>\n  </worldbody>\n</mujoco>\n";
    let path = temp_file("unknown", "unknown.xml", unknown);
    let err = adapter
        .make("X-v0", &config(path))
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("line 3"), "{err}");

    let err = adapter
        .make("X-v0", &EnvConfig::default())
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("needs the model file"), "{err}");

    let mut cfg = config(planar_walker());
    cfg.extra
        .insert("forward_reward_body".into(), json!("head"));
    let err = adapter.make("X-v0", &cfg).err().unwrap().to_string();
    assert!(err.contains("no body `head`"), "{err}");
}

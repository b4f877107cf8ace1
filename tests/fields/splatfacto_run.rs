//! nerfstudio splatfacto runs read as splats: the checkpoint's `gauss_params` activated as
//! splatfacto defines them (exp of the scales, sigmoid of the opacities, normalised w x y z
//! quaternions; `sigmoid(features_dc)` colour when `sh_degree` is 0, SH otherwise), checked
//! against values computed here from the stored ones; the run loads through a scene file, the
//! command line's info, and never as a nerfacto field.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common_nerfacto::{checkpoint_of, STEP};
use glam::Vec3;
use nerfx_core::field::{NerfactoField, SplatColor, Splats};

const N: usize = 5;

struct Stored {
    means: Vec<f32>,
    scales: Vec<f32>,
    quats: Vec<f32>,
    dc: Vec<f32>,
    rest: Vec<f32>,
    opacities: Vec<f32>,
}

fn stored(sh_degree: usize) -> Stored {
    let k = (sh_degree + 1) * (sh_degree + 1) - 1;
    let v = |n: usize, salt: f32| -> Vec<f32> {
        (0..n)
            .map(|i| ((i as f32 + salt) * 0.7368).sin() * 1.3)
            .collect()
    };
    Stored {
        means: v(N * 3, 0.1),
        scales: v(N * 3, 0.2).iter().map(|s| s - 3.0).collect(),
        quats: v(N * 4, 0.3),
        dc: v(N * 3, 0.4),
        rest: v(N * k * 3, 0.5),
        opacities: v(N, 0.6),
    }
}

fn write_run(dir: &Path, method: &str, sh_degree: usize, s: &Stored) -> PathBuf {
    let run = dir.join(format!("{method}-{sh_degree}"));
    let models = run.join("nerfstudio_models");
    std::fs::create_dir_all(&models).unwrap();
    std::fs::write(
        run.join("config.yml"),
        format!(
            "!!python/object:nerfstudio.engine.trainer.TrainerConfig\n\
             method_name: {method}\n\
             pipeline: !!python/object:nerfstudio.pipelines.base_pipeline.VanillaPipelineConfig\n  \
               model: !!python/object:nerfstudio.models.splatfacto.SplatfactoModelConfig\n    \
                 sh_degree: {sh_degree}\n    \
                 rasterize_mode: classic\n"
        ),
    )
    .unwrap();
    let k = (sh_degree + 1) * (sh_degree + 1) - 1;
    let g = "_model.gauss_params.";
    let ckpt = checkpoint_of(&[
        (&format!("{g}means"), vec![N, 3], s.means.clone()),
        (&format!("{g}scales"), vec![N, 3], s.scales.clone()),
        (&format!("{g}quats"), vec![N, 4], s.quats.clone()),
        (&format!("{g}features_dc"), vec![N, 3], s.dc.clone()),
        (&format!("{g}features_rest"), vec![N, k, 3], s.rest.clone()),
        (&format!("{g}opacities"), vec![N, 1], s.opacities.clone()),
    ]);
    std::fs::write(models.join(format!("step-{STEP:09}.ckpt")), ckpt).unwrap();
    run
}

fn close(a: f32, b: f32) -> bool {
    (a - b).abs() <= 1e-6 * b.abs().max(1.0)
}

#[test]
fn splatfacto_runs_read_as_activated_splats() {
    let dir = tempfile::tempdir().unwrap();
    for sh_degree in [0, 3] {
        let s = stored(sh_degree);
        let run = write_run(dir.path(), "splatfacto", sh_degree, &s);
        for path in [run.clone(), run.join("config.yml")] {
            let splats = Splats::load(&path).unwrap();
            assert_eq!((splats.len(), splats.dropped), (N, 0));
            let k = (sh_degree + 1) * (sh_degree + 1);
            assert_eq!(
                splats.color,
                if sh_degree == 0 {
                    SplatColor::Sigmoid
                } else {
                    SplatColor::Sh { degree: 3 }
                }
            );
            for i in 0..N {
                let m = Vec3::from_slice(&s.means[3 * i..]);
                assert_eq!(splats.means[i], m);
                for a in 0..3 {
                    assert!(close(splats.scales[i][a], s.scales[3 * i + a].exp()));
                }
                let q = &s.quats[4 * i..4 * i + 4];
                let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt();
                let r = splats.rotations[i];
                for (got, want) in [r.w, r.x, r.y, r.z].iter().zip(q) {
                    assert!(close(*got, want / norm), "quaternion {i}");
                }
                let o = 1.0 / (1.0 + (-s.opacities[i]).exp());
                assert!(close(splats.opacities[i], o));
                let c = &splats.coefficients[3 * k * i..3 * k * (i + 1)];
                assert_eq!(&c[..3], &s.dc[3 * i..3 * i + 3]);
                assert_eq!(&c[3..], &s.rest[3 * (k - 1) * i..3 * (k - 1) * (i + 1)]);
            }
        }
    }
}

#[test]
fn older_runs_with_the_parameters_on_the_model_read_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let s = stored(3);
    let run = write_run(dir.path(), "splatfacto", 3, &s);
    let new = Splats::load(&run).unwrap();
    let ckpt = run
        .join("nerfstudio_models")
        .join(format!("step-{STEP:09}.ckpt"));
    let g = "_model.";
    std::fs::write(
        &ckpt,
        checkpoint_of(&[
            (&format!("{g}means"), vec![N, 3], s.means.clone()),
            (&format!("{g}scales"), vec![N, 3], s.scales.clone()),
            (&format!("{g}quats"), vec![N, 4], s.quats.clone()),
            (&format!("{g}features_dc"), vec![N, 3], s.dc.clone()),
            (&format!("{g}features_rest"), vec![N, 15, 3], s.rest.clone()),
            (&format!("{g}opacities"), vec![N, 1], s.opacities.clone()),
        ]),
    )
    .unwrap();
    assert_eq!(Splats::load(&run).unwrap(), new);
}

#[test]
fn a_splatfacto_run_is_splats_everywhere_and_never_a_nerfacto_field() {
    let dir = tempfile::tempdir().unwrap();
    let run = write_run(dir.path(), "splatfacto-big", 1, &stored(1));
    let err = NerfactoField::load(&run).err().unwrap().to_string();
    assert!(
        err.contains("splatfacto") && err.contains("splats"),
        "{err}"
    );
    // Named as a nerfacto field in a scene file, it says what it is and how to name it.
    let scene = dir.path().join("scene.json");
    let text = serde_json::json!({"instances": [{"name": "poster",
        "field": {"nerfacto": {"path": run.to_string_lossy()}}}]});
    std::fs::write(&scene, text.to_string()).unwrap();
    let err = nerfx_core::scene::SceneDesc::read(&scene)
        .unwrap()
        .load()
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("splatfacto run") && err.contains("{\"splats\": {\"path\""),
        "{err}"
    );

    let info = Command::new(env!("CARGO_BIN_EXE_nerfx"))
        .arg("info")
        .arg(&run)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(
        info.status.success(),
        "{}",
        String::from_utf8_lossy(&info.stderr)
    );
    assert!(
        text.contains("5 splats") && text.contains("degree 1"),
        "{text}"
    );

    let scene = nerfx_core::scene::SceneDesc::for_path(&run)
        .unwrap()
        .load()
        .unwrap();
    let placed = scene
        .place(glam::DMat4::IDENTITY, &|_| unreachable!())
        .unwrap();
    assert_eq!((placed.marched().count(), placed.splats().count()), (0, 1));

    // Another method is refused by name.
    let other = write_run(dir.path(), "instant-ngp", 1, &stored(1));
    let err = NerfactoField::load(&other).err().unwrap().to_string();
    assert!(err.contains("'instant-ngp' run"), "{err}");

    // A wrong degree in the config names the tensor and its shape.
    let bad = write_run(dir.path(), "splatfacto", 1, &stored(1));
    let cfg = std::fs::read_to_string(bad.join("config.yml")).unwrap();
    std::fs::write(
        bad.join("config.yml"),
        cfg.replace("sh_degree: 1", "sh_degree: 3"),
    )
    .unwrap();
    let err = Splats::load(&bad).err().unwrap().to_string();
    assert!(
        err.contains("features_rest") && err.contains("shape"),
        "{err}"
    );
}

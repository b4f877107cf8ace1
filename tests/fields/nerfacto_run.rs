//! nerfstudio nerfacto runs: the loader against an independent NumPy evaluation of the same
//! run (`tests/numpy/nerfacto_reference.py`) in both checkpoint layouts, the occupancy it
//! computes, and corrupt input.
//!
//! The NumPy checks need `python3` with `numpy` and are cross-checks: they run with the
//! `cross-checks` feature (`scripts/test.sh`), and fail without the tools, saying so.

use crate::common_fields::{check_rgb, check_sigma, numpy_reference, rel_err};
use crate::common_nerfacto::{scratch, write_run, Spec, STEP};
use glam::Vec3;
use nerfx_core::field::{Aabb, Field, NerfactoField};

/// Seeded points (inside the unit cube and out in the contracted shell) and directions.
fn samples(n: usize, seed: u64) -> (Vec<Vec3>, Vec<Vec3>) {
    crate::common_fields::samples(n, seed, |rng, i| {
        let r = if i % 2 == 0 { 1.0 } else { 2.0 };
        rng.vec(-r, r)
    })
}

fn check_against_numpy(name: &str, spec: &Spec) {
    let dir = scratch(name);
    let run = write_run(&dir, spec);
    let field = NerfactoField::load(&run).unwrap();
    println!("{}", field.describe().lines().last().unwrap());
    let (pts, dirs) = samples(2000, spec.seed + 100);
    let mut sigma = vec![0.0; pts.len()];
    let mut rgb = vec![Vec3::ZERO; pts.len()];
    field.density(&pts, &mut sigma);
    field.radiance(&pts, &dirs, &mut rgb);
    let want = numpy_reference("nerfacto_reference.py", &["numpy"], &run, &pts, &dirs);
    assert_eq!(want.len(), pts.len());
    let (mut max_sigma, mut max_rgb, mut masked) = (0.0f32, 0.0f32, 0);
    for (i, w) in want.iter().enumerate() {
        if sigma[i] == 0.0 && w[0] > 0.0 {
            // Masked by the occupancy grid: the point's cell must be empty, and the density
            // there small (the rule keeps cells whose samples reach an opacity of 1e-3
            // across a cell of diagonal 4/64·√3; allow 10 times that between samples).
            let p = pts[i];
            assert!(
                !field.may_be_occupied(&Aabb::new(p, p)),
                "{name}: sample {i} at {p}: σ zeroed in an occupied cell (NumPy {})",
                w[0]
            );
            let cell_diagonal = 4.0 / 64.0 * 3f32.sqrt();
            assert!(
                w[0] * cell_diagonal < 1e-2,
                "{name}: sample {i} at {p}: σ {} (NumPy) masked as empty",
                w[0]
            );
            masked += 1;
        } else {
            max_sigma = max_sigma.max(check_sigma(name, i, pts[i], sigma[i], w));
        }
        max_rgb = max_rgb.max(check_rgb(name, i, rgb[i], w));
    }
    assert!(
        masked <= pts.len() * 3 / 4 && (masked > 0) == spec.expect_empty_space,
        "{name}: {masked} of {} samples masked",
        pts.len()
    );
    println!(
        "{name}: max relative error vs NumPy: density {max_sigma:.2e}, colour {max_rgb:.2e}; \
         {masked} samples in empty occupancy cells"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn tcnn_layout_agrees_with_numpy() {
    check_against_numpy("tcnn", &Spec::tcnn());
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn torch_fallback_layout_agrees_with_numpy() {
    check_against_numpy("torch", &Spec::torch());
}

#[test]
fn describe_names_the_run_and_architecture() {
    let dir = scratch("describe");
    let run = write_run(&dir, &Spec::tcnn());
    let text = nerfx_core::field::describe(&run).unwrap();
    println!("{text}");
    for want in [
        "nerfacto",
        &format!("step {STEP}"),
        "tiny-cuda-nn",
        "16 levels x 2 features",
        "average_init_density 0.01",
        "fill ratio",
    ] {
        assert!(text.contains(want), "missing '{want}' in:\n{text}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn occupancy_is_conservative_at_sampled_points() {
    let dir = scratch("occupancy");
    let run = write_run(&dir, &Spec::tcnn());
    let field = NerfactoField::load(&run).unwrap();
    // The field reaches the far plane (config.yml's, nerfacto's 1000 by default): the
    // contraction maps all of space into the hash grid.
    let b = field.bounds();
    assert_eq!((b.min, b.max), (Vec3::splat(-1000.0), Vec3::splat(1000.0)));
    // Wherever the density is non-zero, the point's region is occupied (in the unit cube, the
    // near shell and out to the far plane); outside the bounds the density is zero.
    let (mut pts, _) = samples(4000, 5);
    let (far, _) = crate::common_fields::samples(4000, 6, |rng, i| {
        let r = [5.0, 40.0, 999.0][i % 3];
        rng.vec(-r, r)
    });
    pts.extend(far);
    let mut sigma = vec![0.0; pts.len()];
    field.density(&pts, &mut sigma);
    for (p, s) in pts.iter().zip(&sigma) {
        if *s > 0.0 {
            assert!(field.may_be_occupied(&Aabb::new(*p, *p)), "{p}");
        }
    }
    // The point query is the density's own mask: "empty" only where the density is zero,
    // and wherever the box query already says so; NaN and points past the far plane too.
    pts.extend([
        Vec3::splat(f32::NAN),
        Vec3::new(0.0, f32::NAN, 0.0),
        Vec3::new(1000.5, 0.0, 0.0),
        Vec3::splat(f32::INFINITY),
    ]);
    sigma.resize(pts.len(), 1.0);
    field.density(&pts, &mut sigma);
    let mut empty = vec![false; pts.len()];
    field.certainly_empty(&pts, &mut empty);
    for ((p, s), e) in pts.iter().zip(&sigma).zip(&empty) {
        assert!(!e || *s == 0.0, "{p}: said empty, density {s}");
        assert!(*e || field.may_be_occupied(&Aabb::new(*p, *p)), "{p}");
    }
    assert!(empty[pts.len() - 4..].iter().all(|e| *e));
    let beyond = [Vec3::new(1000.5, 0.0, 0.0), Vec3::new(0.0, -7.0, 1e4)];
    let mut s = [1.0; 2];
    field.density(&beyond, &mut s);
    assert_eq!(s, [0.0, 0.0]);
    assert!(!field.may_be_occupied(&Aabb::new(Vec3::splat(1001.0), Vec3::splat(1e4))));
    // The seeded run has density in the shell, where the field used to end.
    let mut s = [0.0; 1];
    field.density(&[Vec3::new(2.5, 0.0, 0.0)], &mut s);
    assert!(s[0] > 0.0);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn corrupt_and_truncated_runs_are_errors_naming_the_file() {
    let dir = scratch("corrupt");
    let run = write_run(&dir, &Spec::tcnn());
    let ckpt = run.join(format!("nerfstudio_models/step-{STEP:09}.ckpt"));
    let good = std::fs::read(&ckpt).unwrap();
    // Truncations at many places, and flipped bytes through the whole file.
    let cuts = (0..good.len()).step_by(good.len() / 97 + 1);
    for cut in cuts {
        std::fs::write(&ckpt, &good[..cut]).unwrap();
        let e = NerfactoField::load(&run).expect_err("truncated checkpoint accepted");
        assert!(e.to_string().contains("step-"), "cut {cut}: {e}");
    }
    for at in (0..good.len()).step_by(good.len() / 211 + 1) {
        let mut bad = good.clone();
        bad[at] ^= 0x5A;
        std::fs::write(&ckpt, &bad).unwrap();
        // Any outcome but a panic (a flip in padding is harmless); errors name the file.
        if let Err(e) = NerfactoField::load(&run) {
            assert!(e.to_string().contains("step-"), "flip at {at}: {e}");
        }
    }
    std::fs::write(&ckpt, &good).unwrap();
    // A missing config or dataparser file is named.
    std::fs::remove_file(run.join("dataparser_transforms.json")).unwrap();
    let e = NerfactoField::load(&run).unwrap_err().to_string();
    assert!(e.contains("dataparser_transforms.json"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn scene_files_name_runs_relative_to_themselves() {
    let dir = scratch("scene");
    write_run(&dir, &Spec::tcnn());
    let scene = dir.join("scene.json");
    std::fs::write(
        &scene,
        r#"{"instances": [{"name": "poster", "field": {"nerfacto": {"path": "run"}}}]}"#,
    )
    .unwrap();
    let loaded = nerfx_core::scene::SceneDesc::read(&scene)
        .unwrap()
        .load()
        .unwrap();
    assert_eq!(loaded.desc().instances.len(), 1);
    // It renders: alpha in [0, 1], some coverage.
    {
        use glam::{DMat4, DVec3};
        use nerfx_core::camera::{Camera, Perspective, Projection};
        use nerfx_core::render::{render, Outputs, Quality, RenderSettings};
        let placed = loaded
            .place(DMat4::IDENTITY, &|_| Ok(DMat4::IDENTITY))
            .unwrap();
        let p = Perspective::from_vertical_fov(16, 12, 50.0).unwrap();
        let eye = DVec3::new(0.5, -5.0, 1.0);
        let camera = Camera::new(
            nerfx_core::demo::look_at(eye, DVec3::ZERO),
            Projection::Perspective(p),
        )
        .unwrap();
        let settings = RenderSettings::new(Quality::Draft.params(), Outputs::all());
        let planes = render(&placed, &camera, camera.full_window(), &settings).unwrap();
        let alpha = planes.alpha.as_ref().unwrap();
        let mut covered = 0;
        for (x, y) in (0..12).flat_map(|y| (0..16).map(move |x| (x, y))) {
            let a = alpha.get(x, y);
            assert!((0.0..=1.0 + 1e-5).contains(&a), "alpha {a} at ({x}, {y})");
            covered += usize::from(a > 0.01);
        }
        assert!(covered > 16 * 12 / 2, "{covered} pixels covered");
    }
    // A missing run is an error naming it.
    std::fs::write(
        &scene,
        r#"{"instances": [{"name": "x", "field": {"nerfacto": {"path": "nowhere"}}}]}"#,
    )
    .unwrap();
    let e = nerfx_core::scene::SceneDesc::read(&scene)
        .unwrap()
        .load()
        .err()
        .expect("a missing run loaded")
        .to_string();
    assert!(e.contains("nowhere"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn the_features_path_gives_the_same_samples() {
    for spec in [Spec::tcnn(), Spec::torch()] {
        let dir = scratch(&format!("features-{}", spec.seed));
        let run = write_run(&dir, &spec);
        let field = NerfactoField::load(&run).unwrap();
        let (mut pts, dirs) = samples(700, 9);
        // Beyond the far plane's cube (the field ends there), and out in the contracted shell.
        pts[0] = Vec3::new(1500.0, 0.0, 0.0);
        pts[1] = Vec3::new(-40.0, 300.0, 2.5);
        let n = pts.len();
        let (mut sigma, mut rgb) = (vec![0.0; n], vec![Vec3::ZERO; n]);
        field.density(&pts, &mut sigma);
        field.radiance(&pts, &dirs, &mut rgb);
        assert_eq!(field.feature_count(), 15);
        let (mut sigma2, mut rgb2) = (vec![0.0; n], vec![Vec3::ZERO; n]);
        let mut features = vec![0.0; n * 15];
        field.density_with_features(&pts, &mut sigma2, &mut features);
        field.radiance_with_features(&pts, &dirs, &features, &mut rgb2);
        for i in 0..n {
            assert!(
                rel_err(sigma2[i], sigma[i]) <= 1e-6,
                "{i}: {} vs {}",
                sigma2[i],
                sigma[i]
            );
            for k in 0..3 {
                assert!(
                    rel_err(rgb2[i][k], rgb[i][k]) <= 1e-6,
                    "{i}: {} vs {}",
                    rgb2[i],
                    rgb[i]
                );
            }
        }
        assert_eq!(sigma2[0], 0.0);
        let _ = std::fs::remove_dir_all(&dir);
    }
}

/// The occupancy decision at a lattice of small boxes over the bounds (what a cached grid
/// must reproduce).
fn occupancy_pattern(field: &NerfactoField) -> Vec<bool> {
    let h = 4.0 / 40.0;
    (0..40 * 40 * 40)
        .map(|i| {
            let c = Vec3::new((i % 40) as f32, (i / 40 % 40) as f32, (i / 1600) as f32);
            let lo = Vec3::splat(-2.0) + c * h + Vec3::splat(0.3 * h);
            field.may_be_occupied(&Aabb::new(lo, lo + Vec3::splat(0.2 * h)))
        })
        .collect()
}

#[test]
fn the_occupancy_grid_is_cached_next_to_the_run() {
    let dir = scratch("occupancy-cache");
    // The torch-layout run has empty space (a grid that is neither empty nor full).
    let run = write_run(&dir, &Spec::torch());
    let cache = run.join("nerfx_occupancy.bin");
    let occupancy_line = |f: &NerfactoField| {
        let text = f.describe();
        text.lines().last().unwrap_or_default().to_string()
    };
    // First load: computed, and the cache written.
    let first = NerfactoField::load(&run).unwrap();
    assert!(
        occupancy_line(&first).contains("computed at load"),
        "{}",
        first.describe()
    );
    assert!(cache.is_file());
    let want = occupancy_pattern(&first);
    assert!(want.iter().any(|&o| o) && !want.iter().all(|&o| o));
    // Second load: read from the cache, the same grid.
    let second = NerfactoField::load(&run).unwrap();
    assert!(occupancy_line(&second).contains("read from nerfx_occupancy.bin"));
    assert_eq!(
        occupancy_line(&second),
        occupancy_line(&first).replace("computed at load", "read from nerfx_occupancy.bin")
    );
    assert_eq!(occupancy_pattern(&second), want);
    // A corrupted cache (one flipped byte in the cells, then a truncated one) is ignored:
    // recomputed, the same grid, and rewritten.
    let good = std::fs::read(&cache).unwrap();
    let mut bad = good.clone();
    let at = good.len() - 100;
    bad[at] ^= 0x01;
    std::fs::write(&cache, &bad).unwrap();
    let third = NerfactoField::load(&run).unwrap();
    assert!(occupancy_line(&third).contains("computed at load"));
    assert_eq!(occupancy_pattern(&third), want);
    assert_eq!(std::fs::read(&cache).unwrap(), good);
    std::fs::write(&cache, &good[..good.len() / 2]).unwrap();
    let fourth = NerfactoField::load(&run).unwrap();
    assert!(occupancy_line(&fourth).contains("computed at load"));
    assert_eq!(occupancy_pattern(&fourth), want);
    // A rewritten checkpoint (same bytes, new modification time) makes the cache stale.
    std::thread::sleep(std::time::Duration::from_millis(20));
    let ckpt = run.join(format!("nerfstudio_models/step-{STEP:09}.ckpt"));
    let bytes = std::fs::read(&ckpt).unwrap();
    std::fs::write(&ckpt, &bytes).unwrap();
    let fifth = NerfactoField::load(&run).unwrap();
    assert!(occupancy_line(&fifth).contains("computed at load"));
    assert_eq!(occupancy_pattern(&fifth), want);
    assert!(occupancy_line(&NerfactoField::load(&run).unwrap()).contains("read from"));
    // Garbage of any length (random bytes, then bytes starting like a cache) is ignored.
    let mut rng = crate::common_nerfacto::SplitMix64::new(3);
    let noise: Vec<u8> = (0..5000).map(|_| (rng.next_u64() >> 56) as u8).collect();
    for garbage in [
        noise.as_slice(),
        b"NERFXOCC\x02\x00\x00\x00\xff\xff\xff\xff".as_slice(),
    ] {
        std::fs::write(&cache, garbage).unwrap();
        let again = NerfactoField::load(&run).unwrap();
        assert!(occupancy_line(&again).contains("computed at load"));
        assert_eq!(occupancy_pattern(&again), want);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `nerfx info` on a run, with the per-user cache directory at `cache_home`: its occupancy
/// line.
fn info_occupancy(run: &std::path::Path, cache_home: &std::path::Path) -> String {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_nerfx"))
        .arg("info")
        .arg(run)
        .env("XDG_CACHE_HOME", cache_home)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    text.lines()
        .find(|l| l.starts_with("occupancy:"))
        .unwrap_or_else(|| panic!("no occupancy line in:\n{text}"))
        .to_string()
}

/// A run directory that cannot hold the cache (read-only; when the tests run as root, who
/// may write anyway, a directory in the cache file's place): the grid is cached in the
/// per-user cache directory instead, and read from there; garbage and another run's cache
/// there are ignored and replaced.
#[test]
fn the_occupancy_cache_falls_back_to_the_user_cache_directory() {
    use std::os::unix::fs::PermissionsExt;
    let dir = scratch("occupancy-fallback");
    let other = write_run(&dir.join("other"), &Spec::tcnn());
    let foreign = info_occupancy(&other, &dir.join("unused"));
    assert!(foreign.contains("computed at load"), "{foreign}");
    let run = write_run(&dir, &Spec::torch());
    let cache_home = dir.join("cache-home");
    std::fs::set_permissions(&run, std::fs::Permissions::from_mode(0o555)).unwrap();
    let probe = run.join("probe");
    let read_only = std::fs::write(&probe, b"").is_err();
    if !read_only {
        println!("running as a user who may write a read-only directory: a directory takes the cache file's place instead");
        std::fs::remove_file(&probe).unwrap();
        std::fs::set_permissions(&run, std::fs::Permissions::from_mode(0o755)).unwrap();
        std::fs::create_dir(run.join("nerfx_occupancy.bin")).unwrap();
    }
    let first = info_occupancy(&run, &cache_home);
    assert!(first.contains("computed at load"), "{first}");
    assert!(!run.join("nerfx_occupancy.bin").is_file());
    let cached: Vec<_> = std::fs::read_dir(cache_home.join("nerfx"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(cached.len(), 1, "{cached:?}");
    let second = info_occupancy(&run, &cache_home);
    assert_eq!(
        second,
        first.replace(
            "computed at load",
            &format!("read from {}", cached[0].display())
        )
    );
    for bad in [
        b"not a grid".to_vec(),
        std::fs::read(other.join("nerfx_occupancy.bin")).unwrap(),
    ] {
        std::fs::write(&cached[0], bad).unwrap();
        assert_eq!(info_occupancy(&run, &cache_home), first);
        assert_eq!(info_occupancy(&run, &cache_home), second);
    }
    std::fs::set_permissions(&run, std::fs::Permissions::from_mode(0o755)).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A checkpoint whose training diverged is refused naming the tensor, and an empty
/// `config.yml` is called empty rather than blaming the checkpoint for not matching it.
#[test]
fn nan_weights_and_an_empty_config_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let spec = Spec {
        density_offset: f32::NAN,
        ..Spec::torch()
    };
    let run = write_run(dir.path(), &spec);
    let e = NerfactoField::load(&run).unwrap_err().to_string();
    assert!(
        e.contains(&format!("step-{STEP:09}.ckpt"))
            && e.contains("_model.field.mlp_base.model.1.layers.1.bias")
            && e.contains("1 of 16 weights are NaN or infinite"),
        "{e}"
    );

    let run = write_run(&dir.path().join("empty"), &Spec::tcnn());
    std::fs::write(run.join("config.yml"), "").unwrap();
    let e = NerfactoField::load(&run).unwrap_err().to_string();
    assert!(e.contains("config.yml: is empty"), "{e}");
    assert!(!e.contains("step-"), "{e}");
}

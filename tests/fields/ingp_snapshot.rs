//! instant-ngp snapshots: the loader against an independent NumPy evaluation of the same
//! files (`tests/numpy/ingp_reference.py`), the occupancy it gives, and corrupt input.
//!
//! The NumPy checks need `python3` with `numpy` and `msgpack` and are cross-checks: they run with the
//! `cross-checks` feature (`scripts/test.sh`), and fail without the tools, saying so.

use std::process::Command;

use crate::common_fields::{check_rgb, check_sigma, numpy_reference};
use crate::common_ingp::{scratch, write_snapshot, Spec, SplitMix64};
use glam::Vec3;
use nerfx_core::field::{Aabb, Field, IngpField, TableStorage};

/// Seeded points inside the field's bounds and unit directions.
fn samples(field: &IngpField, n: usize, seed: u64) -> (Vec<Vec3>, Vec<Vec3>) {
    let b = field.bounds();
    crate::common_fields::samples_in_box(b.min, b.max, n, seed)
}

fn check_against_numpy(name: &str, spec: &Spec) {
    let dir = scratch(name);
    let path = write_snapshot(&dir, name, spec);
    let field = IngpField::load(&path).unwrap();
    let (pts, dirs) = samples(&field, 3000, spec.seed + 100);
    let mut sigma = vec![0.0; pts.len()];
    let mut rgb = vec![Vec3::ZERO; pts.len()];
    field.density(&pts, &mut sigma);
    field.radiance(&pts, &dirs, &mut rgb);
    let occupied = sigma.iter().filter(|&&s| s > 0.0).count();
    assert!(
        occupied > 300 && occupied < 2700,
        "{name}: {occupied} occupied samples"
    );
    let want = numpy_reference(
        "ingp_reference.py",
        &["numpy", "msgpack"],
        &path,
        &pts,
        &dirs,
    );
    assert_eq!(want.len(), pts.len());
    let (mut max_sigma, mut max_rgb) = (0.0f32, 0.0f32);
    for (i, w) in want.iter().enumerate() {
        max_sigma = max_sigma.max(check_sigma(name, i, pts[i], sigma[i], w));
        max_rgb = max_rgb.max(check_rgb(name, i, rgb[i], w));
    }
    println!("{name}: max relative error vs NumPy: density {max_sigma:.2e}, colour {max_rgb:.2e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn current_8x4_fp16_gzip_agrees_with_numpy() {
    check_against_numpy("8x4", &Spec::small_8x4());
}

#[test]
#[cfg_attr(
    not(feature = "cross-checks"),
    ignore = "a cross-check: scripts/test.sh runs it"
)]
fn old_16x2_float_cutlass_hdr_agrees_with_numpy() {
    check_against_numpy("16x2", &Spec::old_16x2());
}

#[test]
fn bounds_follow_the_dataset_transform() {
    // aabb_scale 4: the training box is 0.5 ± 2 in instant-ngp units, clipped to the
    // 3 cascades (0.5 ± 2); with s = 0.5 and o = (0.4, 0.6, 0.45) the NeRF-world box is
    // x ∈ ((−1.5 − 0.4)/0.5, (2.5 − 0.4)/0.5) (x comes from instant-ngp's z), and so on.
    let dir = scratch("bounds");
    let path = write_snapshot(&dir, "b", &Spec::old_16x2());
    let f = IngpField::load(&path).unwrap();
    let b = f.bounds();
    let want_min = Vec3::new((-1.5 - 0.4) / 0.5, (-1.5 - 0.6) / 0.5, (-1.5 - 0.45) / 0.5);
    let want_max = Vec3::new((2.5 - 0.4) / 0.5, (2.5 - 0.6) / 0.5, (2.5 - 0.45) / 0.5);
    assert!((b.min - want_min).abs().max_element() < 1e-5, "{:?}", b);
    assert!((b.max - want_max).abs().max_element() < 1e-5, "{:?}", b);
    // Instant-ngp's smallest step √3/1024 of its unit, in NeRF units.
    assert!((f.feature_size() - 3f32.sqrt() / 1024.0 / 0.5).abs() < 1e-9);
    let text = f.describe();
    for part in [
        "16 levels x 2 features",
        "msgpack",
        "float",
        "output padding 8",
        "3 cascades",
    ] {
        assert!(text.contains(part), "{part} missing from:\n{text}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn smooth_length_is_the_finest_grid_cell_in_field_units() {
    // 8 levels from N_min 16 to 2048·aabb_scale (aabb_scale 2): the finest level's scale is
    // 16·(4096/16)^(7/7) − 1 = 4095 cells across the training box's side of 2 instant-ngp
    // units, which are 1/0.33 field units each.
    let spec = Spec::small_8x4();
    assert_eq!(
        (spec.n_levels, spec.base_resolution, spec.aabb_scale),
        (8, 16, 2)
    );
    assert_eq!(spec.scale, 0.33);
    let dir = scratch("smooth-length");
    let field = IngpField::load(&write_snapshot(&dir, "s", &spec)).unwrap();
    let want = 2.0 / 4095.0 / 0.33;
    let got = field.smooth_length();
    assert!((got / want - 1.0).abs() < 1e-4, "{got} vs {want}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn occupancy_is_conservative_where_the_field_has_density() {
    let dir = scratch("occ");
    let path = write_snapshot(&dir, "o", &Spec::small_8x4());
    let f = IngpField::load(&path).unwrap();
    let (pts, _) = samples(&f, 4000, 9);
    let mut sigma = vec![0.0; pts.len()];
    f.density(&pts, &mut sigma);
    let occ = nerfx_core::field::Occupancy::build(&f, 64);
    let mut empty_seen = 0;
    for (p, s) in pts.iter().zip(&sigma) {
        let tiny = nerfx_core::field::Aabb::new(*p, *p);
        if *s > 0.0 {
            assert!(f.may_be_occupied(&tiny), "{p}");
            assert!(occ.is_occupied_point(*p), "{p}");
        } else if !f.may_be_occupied(&tiny) {
            empty_seen += 1;
        }
    }
    assert!(empty_seen > 100, "{empty_seen}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The point query is the density's own mask: "empty" only where the density is exactly
/// zero, and, at points inside a cell, what a box query of the point says. On a cell's face
/// the point belongs to one cell while the box query, padded, sees both: there it may say
/// "empty" where the box query does not, never the reverse. Points: cell centres jittered
/// within the cell, points on cell faces, points beyond the bounds, and NaN.
#[test]
fn certainly_empty_is_the_density_mask_cell_for_cell() {
    let dir = scratch("empty");
    let spec = Spec {
        log2_table_size: 12,
        ..Spec::fog_sphere()
    };
    let f = IngpField::load(&write_snapshot(&dir, "e", &spec)).unwrap();
    let b = f.bounds();
    // One cascade over the bounds: 128 cells per axis.
    let cell = b.size() / 128.0;
    let mut rng = SplitMix64::new(17);
    let mut inside = Vec::new();
    let mut faces = Vec::new();
    for _ in 0..4000 {
        let k = Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 128.0;
        let centre = b.min + (k.floor() + Vec3::splat(0.5)) * cell;
        inside
            .push(centre + Vec3::new(rng.unit(), rng.unit(), rng.unit()) * 0.6 * cell - 0.3 * cell);
        let mut on_face = b.min + k * cell;
        on_face.x = b.min.x + k.x.floor() * cell.x;
        faces.push(on_face);
    }
    let others = [
        Vec3::splat(f32::NAN),
        Vec3::new(0.0, f32::NAN, 0.0),
        b.max + Vec3::ONE,
        b.min - Vec3::ONE,
        Vec3::splat(1e30),
        Vec3::splat(f32::INFINITY),
        b.min,
        b.max,
    ];
    let points: Vec<Vec3> = inside
        .iter()
        .chain(&faces)
        .chain(&others)
        .copied()
        .collect();
    let mut empty = vec![false; points.len()];
    f.certainly_empty(&points, &mut empty);
    let mut sigma = vec![0.0; points.len()];
    f.density(&points, &mut sigma);
    for (i, ((p, e), s)) in points.iter().zip(&empty).zip(&sigma).enumerate() {
        assert!(!e || *s == 0.0, "point {i} {p}: said empty, density {s}");
        let boxed = f.may_be_occupied(&Aabb::new(*p, *p));
        if i < inside.len() {
            assert_eq!(*e, !boxed, "point {i} {p} inside a cell");
        } else {
            assert!(
                *e || boxed,
                "point {i} {p}: occupied, but not for the box query"
            );
        }
    }
    assert!(empty[inside.len() + faces.len()..].iter().all(|e| *e));
    // Both answers are common, and the faces of the ball's rim give both too.
    let count = |r: std::ops::Range<usize>| empty[r].iter().filter(|e| **e).count();
    let (n, m) = (inside.len(), faces.len());
    assert!((500..n - 500).contains(&count(0..n)), "{}", count(0..n));
    assert!(
        (500..m - 500).contains(&count(n..n + m)),
        "{}",
        count(n..n + m)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn table_storages_agree() {
    let dir = scratch("storage");
    let path = write_snapshot(&dir, "s", &Spec::small_8x4());
    let a = IngpField::load_with(&path, Some(TableStorage::F16)).unwrap();
    let b = IngpField::load_with(&path, Some(TableStorage::F32)).unwrap();
    let (pts, dirs) = samples(&a, 500, 4);
    let (mut sa, mut sb) = (vec![0.0; 500], vec![0.0; 500]);
    a.density(&pts, &mut sa);
    b.density(&pts, &mut sb);
    let (mut ca, mut cb) = (vec![Vec3::ZERO; 500], vec![Vec3::ZERO; 500]);
    a.radiance(&pts, &dirs, &mut ca);
    b.radiance(&pts, &dirs, &mut cb);
    // fp16 tables widen exactly: both storages give the same numbers.
    assert_eq!(sa, sb);
    assert_eq!(ca, cb);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn truncated_and_corrupt_files_give_errors_naming_the_file() {
    let dir = scratch("corrupt");
    for spec in [Spec::small_8x4(), Spec::old_16x2()] {
        let full = crate::common_ingp::file_bytes(&spec);
        let path = dir.join(if spec.gzip { "cut.ingp" } else { "cut.msgpack" });
        let mut cuts: Vec<usize> = (0..64).map(|k| k * full.len() / 64).collect();
        cuts.extend([1, 2, 3, 10, 100, full.len() - 1]);
        for cut in cuts {
            std::fs::write(&path, &full[..cut]).unwrap();
            let e = IngpField::load(&path)
                .err()
                .unwrap_or_else(|| panic!("cut at {cut} loaded"));
            let msg = e.to_string();
            assert!(msg.contains("cut."), "cut at {cut}: {msg}");
        }
        // Flipped bytes: an error or a field, never a panic.
        let mut rng = SplitMix64::new(5);
        for _ in 0..40 {
            let mut bad = full.clone();
            let i = (rng.next_u64() % bad.len().min(4096) as u64) as usize;
            bad[i] ^= 0x5a;
            std::fs::write(&path, &bad).unwrap();
            if let Err(e) = IngpField::load(&path) {
                assert!(e.to_string().contains("cut."), "{e}");
            }
        }
    }
    let missing = IngpField::load(&dir.join("missing.ingp")).err().unwrap();
    assert!(missing.to_string().contains("missing.ingp"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_scene_file_renders_a_snapshot_next_to_it() {
    use glam::{DMat4, DVec3};
    use nerfx_core::camera::{Camera, Perspective, Projection};
    use nerfx_core::render::{render, Outputs, Quality, RenderSettings};
    let dir = scratch("scene");
    write_snapshot(&dir, "obj", &Spec::small_8x4());
    let scene_path = dir.join("scene.json");
    std::fs::write(
        &scene_path,
        r#"{ "instances": [ { "name": "obj", "field": { "ingp": { "path": "obj.ingp" } } } ] }"#,
    )
    .unwrap();
    let scene = nerfx_core::scene::SceneDesc::read(&scene_path)
        .unwrap()
        .load()
        .unwrap()
        .place(DMat4::IDENTITY, &|_| Ok(DMat4::IDENTITY))
        .unwrap();
    let p = Perspective::from_vertical_fov(24, 16, 50.0).unwrap();
    let eye = DVec3::new(0.0, -9.0, 2.0);
    let camera = Camera::new(
        nerfx_core::demo::look_at(eye, DVec3::ZERO),
        Projection::Perspective(p),
    )
    .unwrap();
    let settings = RenderSettings::new(Quality::Draft.params(), Outputs::all());
    let planes = render(&scene, &camera, camera.full_window(), &settings).unwrap();
    let alpha = planes.alpha.as_ref().unwrap();
    let covered = (0..16)
        .flat_map(|y| (0..24).map(move |x| (x, y)))
        .filter(|&(x, y)| alpha.get(x, y) > 0.05)
        .count();
    assert!(covered > 24 * 16 / 4, "{covered} pixels covered");
    for (x, y) in (0..16).flat_map(|y| (0..24).map(move |x| (x, y))) {
        let a = alpha.get(x, y);
        assert!((0.0..=1.0 + 1e-5).contains(&a), "alpha {a} at ({x}, {y})");
    }
    // A missing snapshot is named in the error.
    std::fs::write(
        &scene_path,
        r#"{ "instances": [ { "name": "obj", "field": { "ingp": { "path": "gone.ingp" } } } ] }"#,
    )
    .unwrap();
    let e = nerfx_core::scene::SceneDesc::read(&scene_path)
        .unwrap()
        .load()
        .err()
        .unwrap();
    assert!(e.to_string().contains("gone.ingp"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn nerfx_info_describes_a_snapshot_and_names_a_corrupt_one() {
    let dir = scratch("info");
    let path = write_snapshot(&dir, "garden", &Spec::small_8x4());
    let out = Command::new(env!("CARGO_BIN_EXE_nerfx"))
        .arg("info")
        .arg(&path)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}");
    for part in [
        "gzip msgpack",
        "8 levels x 4 features",
        "__half",
        "2 cascades",
        "fill ratio",
        "bounds",
    ] {
        assert!(text.contains(part), "{part} missing from:\n{text}");
    }
    let bytes = std::fs::read(&path).unwrap();
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_nerfx"))
        .arg("info")
        .arg(&path)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("garden.ingp"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Input that is no snapshot is refused early, naming the file and what it holds: a gzip
/// bomb (512 MiB of zeros in half a megabyte) fails at its first value instead of being
/// inflated whole, random bytes and a msgpack array say they are not a snapshot.
#[test]
fn hostile_snapshots_are_refused_early_in_the_users_terms() {
    use std::io::Write;
    let dir = scratch("hostile");
    let bomb = dir.join("bomb.ingp");
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    let zeros = vec![0u8; 1 << 20];
    for _ in 0..512 {
        gz.write_all(&zeros).unwrap();
    }
    let packed = gz.finish().unwrap();
    assert!(packed.len() < 1 << 20, "{} bytes", packed.len());
    std::fs::write(&bomb, &packed).unwrap();
    let e = IngpField::load(&bomb).err().unwrap().to_string();
    assert!(
        e.contains("bomb.ingp") && e.contains("holds an integer, not a map"),
        "{e}"
    );

    let random = dir.join("random.msgpack");
    let mut rng = SplitMix64::new(11);
    let bytes: Vec<u8> = (0..65536).map(|_| rng.next_u64() as u8).collect();
    std::fs::write(&random, &bytes).unwrap();
    let e = IngpField::load(&random).err().unwrap().to_string();
    assert!(
        e.contains("random.msgpack") && e.contains("not a"),
        "random bytes: {e}"
    );
    assert!(!e.contains("missing key"), "random bytes: {e}");

    let array = dir.join("array.msgpack");
    std::fs::write(&array, [0x90]).unwrap();
    let e = IngpField::load(&array).err().unwrap().to_string();
    assert!(e.contains("holds an array, not a map"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The snapshot of `spec` (raw msgpack) with `edit` applied to the bytes of `snapshot.<key>`.
fn with_snapshot_bytes(spec: &Spec, key: &str, edit: impl Fn(&mut Vec<u8>)) -> Vec<u8> {
    use rmpv::Value;
    let mut top =
        rmpv::decode::read_value(&mut &crate::common_ingp::snapshot_bytes(spec)[..]).unwrap();
    let Value::Map(entries) = &mut top else {
        panic!("top level is not a map")
    };
    let (_, Value::Map(snap)) = entries
        .iter_mut()
        .find(|(k, _)| k.as_str() == Some("snapshot"))
        .unwrap()
    else {
        panic!("snapshot is not a map")
    };
    let (_, Value::Binary(bytes)) = snap
        .iter_mut()
        .find(|(k, _)| k.as_str() == Some(key))
        .unwrap()
    else {
        panic!("{key} is not binary")
    };
    edit(bytes);
    let mut out = Vec::new();
    rmpv::encode::write_value(&mut out, &top).unwrap();
    out
}

/// A diverged training's NaN or infinite weights would render nothing without a word: they
/// are refused at load, naming the file and the block; so is a NaN in the density grid (its
/// negative values, cells no camera saw, are not).
#[test]
fn non_finite_weights_and_density_grid_values_are_refused_naming_the_block() {
    let dir = tempfile::tempdir().unwrap();
    let spec = Spec {
        gzip: false,
        ..Spec::small_8x4()
    };
    let (nd, nr, _) = crate::common_ingp::param_counts(&spec);
    let path = dir.path().join("diverged.msgpack");
    let nan = half::f16::NAN.to_le_bytes();
    let inf = half::f16::INFINITY.to_le_bytes();
    for (index, value, block) in [
        (3, nan, "density MLP"),
        (nd + 7, inf, "rgb MLP"),
        (nd + nr + 100, nan, "hash grid"),
    ] {
        let bytes = with_snapshot_bytes(&spec, "params_binary", |b| {
            b[2 * index..2 * index + 2].copy_from_slice(&value)
        });
        std::fs::write(&path, bytes).unwrap();
        let e = IngpField::load(&path).err().unwrap().to_string();
        assert!(
            e.contains("diverged.msgpack: snapshot.params_binary: the ")
                && e.contains(block)
                && e.contains("1 of ")
                && e.contains("NaN or infinite"),
            "{block}: {e}"
        );
    }
    let bytes = with_snapshot_bytes(&spec, "density_grid_binary", |b| {
        b[10..12].copy_from_slice(&nan);
        b[20..22].copy_from_slice(&half::f16::from_f32(-1.0).to_le_bytes());
    });
    std::fs::write(&path, bytes).unwrap();
    let e = IngpField::load(&path).err().unwrap().to_string();
    assert!(
        e.contains("snapshot.density_grid_binary") && e.contains("1 of ") && e.contains("NaN"),
        "{e}"
    );
    let bytes = with_snapshot_bytes(&spec, "density_grid_binary", |b| {
        b[20..22].copy_from_slice(&half::f16::from_f32(-1.0).to_le_bytes());
        b[30..32].copy_from_slice(&inf);
    });
    std::fs::write(&path, bytes).unwrap();
    IngpField::load(&path).unwrap();
}

/// The snapshot of `spec` with `edit` applied to its `snapshot` map, written as `name`.
fn edited(
    name: &str,
    spec: &Spec,
    edit: impl Fn(&mut Vec<(rmpv::Value, rmpv::Value)>),
) -> std::path::PathBuf {
    let bytes = crate::common_ingp::snapshot_bytes(spec);
    let mut top = rmpv::decode::read_value(&mut &bytes[..]).unwrap();
    let rmpv::Value::Map(entries) = &mut top else {
        panic!("a map")
    };
    for (k, v) in entries.iter_mut() {
        if let (Some("snapshot"), rmpv::Value::Map(snap)) = (k.as_str(), v) {
            edit(snap);
        }
    }
    let mut out = Vec::new();
    rmpv::encode::write_value(&mut out, &top).unwrap();
    let path = scratch("edited").join(name);
    std::fs::write(&path, out).unwrap();
    path
}

/// An inverted render box and a singular box rotation are refused, naming the key; an
/// identity rotation written with whole numbers is read as one.
#[test]
fn inverted_or_singular_render_boxes_are_refused() {
    let spec = Spec {
        n_cascades: 1,
        log2_table_size: 10,
        gzip: false,
        ..Spec::small_8x4()
    };
    let set = |key: &'static str, value: rmpv::Value| {
        move |snap: &mut Vec<(rmpv::Value, rmpv::Value)>| {
            snap.retain(|(k, _)| k.as_str() != Some(key));
            snap.push((rmpv::Value::from(key), value.clone()));
        }
    };
    let f = |v: f64| rmpv::Value::F64(v);
    let row = |a: [f64; 3]| rmpv::Value::Array(a.map(f).to_vec());
    let inverted = rmpv::Value::Map(vec![
        (rmpv::Value::from("min"), row([0.0, 0.9, 0.0])),
        (rmpv::Value::from("max"), row([1.0, 0.1, 1.0])),
    ]);
    let path = edited("inverted.msgpack", &spec, set("render_aabb", inverted));
    let e = IngpField::load(&path).unwrap_err().to_string();
    assert!(
        e.contains("snapshot.render_aabb") && e.contains("inverted") && e.contains(" y"),
        "{e}"
    );

    let singular = rmpv::Value::Array(vec![
        row([1.0, 0.0, 0.0]),
        row([0.0, 0.0, 0.0]),
        row([0.0, 0.0, 1.0]),
    ]);
    let path = edited(
        "singular.msgpack",
        &spec,
        set("render_aabb_to_local", singular),
    );
    let e = IngpField::load(&path).unwrap_err().to_string();
    assert!(
        e.contains("render_aabb_to_local") && e.contains("singular"),
        "{e}"
    );

    let whole = |a: [i64; 3]| rmpv::Value::Array(a.map(rmpv::Value::from).to_vec());
    let identity = rmpv::Value::Array(vec![whole([1, 0, 0]), whole([0, 1, 0]), whole([0, 0, 1])]);
    let plain = IngpField::load(&edited("plain.msgpack", &spec, |_| {})).unwrap();
    let path = edited(
        "identity.msgpack",
        &spec,
        set("render_aabb_to_local", identity),
    );
    assert_eq!(IngpField::load(&path).unwrap().bounds(), plain.bounds());
}

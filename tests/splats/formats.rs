//! The compact splat formats against decodings nobody here wrote, and against writers written
//! here from the formats' descriptions, independent of the readers.
//!
//! - `tests/data/splats/` (made by `scripts/splat_fixtures.sh`): PlayCanvas splat-transform's
//!   encodings of 512 trained splats (compressed PLY, SOG, SPZ 3 and 4) and 512 splats of two
//!   real captures (a `.splat`, a compressed PLY), each with splat-transform's own decoding to
//!   an INRIA PLY. nerfx's reading of each file must equal that decoding splat for splat, and
//!   render like it to ≥ 60 dB.
//! - Writers in this file encode known values as each format's description says (SPZ 2, 3 and
//!   4, `.splat`); the reader must give back the description's decoding of the stored bytes.
//!
//! Whole real captures, too large to keep here, are checked the same way by
//! `NERFX_REAL_SPLATS=folder cargo bench --bench splats -- real_captures`.

use crate::common_splats;

use std::io::Write;
use std::path::{Path, PathBuf};

use common_splats::{assert_matches, check_against_decoding, differences};
use glam::{DMat4, Quat, Vec3};
use nerfx_core::field::{Axes, SplatColor, SplatFormat, Splats};
use nerfx_core::scene::SplatInstance;

fn data(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/splats")
        .join(name)
}

/// Each encoding read by nerfx against splat-transform's decoding of it.
#[test]
fn encodings_equal_splat_transforms_decoding_and_render_alike() {
    // splat-transform 2.7.1 turns SPZ from RUB into the PLY frame as it reads it (see the next
    // test): compare nerfx's reading with "axes": "rub".
    let cases = [
        (
            "subset_sh3.compressed.ply",
            SplatFormat::CompressedPly,
            None,
            3,
            Axes::Stored,
        ),
        ("subset_sh3.sog", SplatFormat::Sog, Some(2), 3, Axes::Stored),
        ("subset_sh3.spz", SplatFormat::Spz, Some(4), 3, Axes::Rub),
        ("subset_sh3.v3.spz", SplatFormat::Spz, Some(3), 3, Axes::Rub),
        (
            "sjeongab_512.splat",
            SplatFormat::Splat,
            None,
            0,
            Axes::Stored,
        ),
        (
            "guitar_512.compressed.ply",
            SplatFormat::CompressedPly,
            None,
            0,
            Axes::Stored,
        ),
    ];
    for (name, format, version, degree, axes) in cases {
        let ours = Splats::load(&data(name)).unwrap();
        assert_eq!(ours.source.format, format, "{name}");
        assert_eq!(ours.source.version, version, "{name}");
        assert_eq!(ours.color, SplatColor::Sh { degree }, "{name}");
        assert_eq!((ours.len(), ours.dropped), (512, 0), "{name}");
        assert_matches(name, check_against_decoding(&data(""), name, axes));
    }
}

/// splat-transform 2.7.1 writes SPZ in RUB, y and z flipped from the PLY it was given (and
/// flips them back as it reads SPZ). nerfx reads the stored values, and `"axes": "rub"` brings
/// them back to the PLY's frame.
#[test]
fn splat_transform_spz_is_rub_and_axes_rub_brings_it_back() {
    let source = Splats::load(&data("subset_sh3.ply")).unwrap();
    let spz = Splats::load(&data("subset_sh3.spz")).unwrap();
    let unit = 1.0 / 4096.0; // 12 fractional bits
    let flipped = |m: Vec3| Vec3::new(m.x, -m.y, -m.z);
    let worst = |a: &Splats, f: &dyn Fn(Vec3) -> Vec3| {
        a.means
            .iter()
            .zip(&source.means)
            .map(|(m, s)| (*m - f(*s)).abs().max_element())
            .fold(0.0f32, f32::max)
    };
    assert!(worst(&spz, &flipped) <= unit, "{}", worst(&spz, &flipped));
    assert!(worst(&spz, &|m| m) > 0.1);
    let back = spz.into_ply_frame(Axes::Rub);
    assert!(worst(&back, &|m| m) <= unit);
    // The colour seen along a direction survives the round trip: the DC term is unchanged,
    // and the first-order terms keep their values to SPZ's 8-bit steps.
    let k = source.color.coefficients() * 3;
    let mut worst_sh1 = 0.0f32;
    for i in 0..source.len() {
        for j in 3..12 {
            let d = back.coefficients[i * k + j] - source.coefficients[i * k + j];
            worst_sh1 = worst_sh1.max(d.abs());
        }
    }
    assert!(worst_sh1 <= 0.07, "first-order SH off by {worst_sh1}");
}

// ---------------------------------------------------------------------------------------
// Writers from the formats' descriptions.

/// A few splats with every field away from special values.
struct Plain {
    mean: Vec3,
    log_scale: Vec3,
    /// `w x y z`, unit.
    rotation: [f32; 4],
    opacity: f32,
    /// 16 × rgb, coefficient-major (DC first).
    sh: [f32; 48],
}

fn plain_splats(n: usize) -> Vec<Plain> {
    (0..n)
        .map(|i| {
            let t = i as f32;
            let q = Quat::from_axis_angle(
                Vec3::new((t * 0.7).sin(), (t * 1.3).cos(), 0.5).normalize(),
                0.3 + t,
            );
            let q = if q.w < 0.0 { -q } else { q };
            let mut sh = [0.0f32; 48];
            for (k, v) in sh.iter_mut().enumerate() {
                *v = ((t + 1.0) * (k as f32 + 0.5) * 0.61).sin() * if k < 3 { 1.5 } else { 0.4 };
            }
            Plain {
                mean: Vec3::new(
                    0.1 * t - 1.0,
                    (t * 0.37).sin(),
                    0.5 * (t * 0.11).cos() - 2.0,
                ),
                log_scale: Vec3::new(-4.0 + 0.05 * t, -3.0, -5.5 + 0.02 * t),
                rotation: [q.w, q.x, q.y, q.z],
                opacity: 0.05 + 0.9 * ((t * 0.77).sin() * 0.5 + 0.5),
                sh,
            }
        })
        .collect()
}

fn byte(v: f32) -> u8 {
    v.round().clamp(0.0, 255.0) as u8
}

/// SPZ attribute streams of `splats` for `version`, and the values they decode to by the
/// description (the expected splats).
fn spz_streams(splats: &[Plain], version: u32, degree: usize) -> ([Vec<u8>; 6], Splats) {
    let dim = (degree + 1).pow(2) - 1;
    let mut s: [Vec<u8>; 6] = Default::default();
    let color = SplatColor::Sh {
        degree: degree as u8,
    };
    let mut want = Splats::with_capacity(splats.len(), color, SplatFormat::Spz);
    for p in splats {
        let mut mean = Vec3::ZERO;
        for k in 0..3 {
            let fixed = (p.mean[k] * 4096.0).round() as i32;
            s[0].extend_from_slice(&fixed.to_le_bytes()[..3]);
            mean[k] = fixed as f32 / 4096.0;
        }
        let a = byte(p.opacity * 255.0);
        s[1].push(a);
        let mut coeffs = vec![0.0f32; (dim + 1) * 3];
        for (k, dc) in coeffs[..3].iter_mut().zip(&p.sh[..3]) {
            let b = byte(dc * 0.15 * 255.0 + 127.5);
            s[2].push(b);
            *k = (f32::from(b) / 255.0 - 0.5) / 0.15;
        }
        let mut scale = Vec3::ZERO;
        for k in 0..3 {
            let b = byte((p.log_scale[k] + 10.0) * 16.0);
            s[3].push(b);
            scale[k] = (f32::from(b) / 16.0 - 10.0).exp();
        }
        let [w, x, y, z] = p.rotation;
        let xyzw = [x, y, z, w];
        let rotation = if version == 2 {
            // w ≥ 0 already: x y z in a byte each.
            let b = [x, y, z].map(|v| byte(v * 127.5 + 127.5));
            s[4].extend_from_slice(&b);
            let v = b.map(|b| f32::from(b) / 127.5 - 1.0);
            let w = (1.0 - v.iter().map(|c| c * c).sum::<f32>()).max(0.0).sqrt();
            [w, v[0], v[1], v[2]]
        } else {
            let largest = (0..4)
                .max_by(|&i, &j| xyzw[i].abs().total_cmp(&xyzw[j].abs()))
                .unwrap();
            let sign = if xyzw[largest] < 0.0 { -1.0 } else { 1.0 };
            let mut comp = largest as u32;
            let mut out = [0.0f32; 4];
            let mut sum = 0.0;
            for (i, &v) in xyzw.iter().enumerate() {
                if i != largest {
                    let v = v * sign;
                    let mag = (511.0 * v.abs() * std::f32::consts::SQRT_2 + 0.5) as u32;
                    comp = (comp << 10) | (u32::from(v < 0.0) << 9) | mag;
                    out[i] = (mag as f32 / 511.0)
                        * std::f32::consts::FRAC_1_SQRT_2
                        * if v < 0.0 { -1.0 } else { 1.0 };
                    sum += out[i] * out[i];
                }
            }
            out[largest] = (1.0 - sum).max(0.0).sqrt();
            s[4].extend_from_slice(&comp.to_le_bytes());
            [out[3], out[0], out[1], out[2]]
        };
        for k in 0..dim {
            for c in 0..3 {
                let b = byte(p.sh[(k + 1) * 3 + c] * 128.0 + 128.0);
                s[5].push(b);
                coeffs[(k + 1) * 3 + c] = (f32::from(b) - 128.0) / 128.0;
            }
        }
        assert!(want.push_activated(mean, scale, rotation, f32::from(a) / 255.0, &coeffs));
    }
    (s, want)
}

/// An SPZ file of version 2 or 3 (one gzip stream) or 4 (zstd streams).
fn spz_file(splats: &[Plain], version: u32, degree: usize, antialiased: bool) -> (Vec<u8>, Splats) {
    let (streams, want) = spz_streams(splats, version, degree);
    let flags = u8::from(antialiased);
    let n = splats.len() as u32;
    let mut header = Vec::new();
    header.extend_from_slice(b"NGSP");
    header.extend_from_slice(&version.to_le_bytes());
    header.extend_from_slice(&n.to_le_bytes());
    if version < 4 {
        header.extend_from_slice(&[degree as u8, 12, flags, 0]);
        let mut raw = header;
        for s in &streams {
            raw.extend_from_slice(s);
        }
        let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        gz.write_all(&raw).unwrap();
        (gz.finish().unwrap(), want)
    } else {
        let present: Vec<&Vec<u8>> = streams.iter().filter(|s| !s.is_empty()).collect();
        header.extend_from_slice(&[degree as u8, 12, flags, present.len() as u8]);
        header.extend_from_slice(&32u32.to_le_bytes());
        header.extend_from_slice(&[0; 12]);
        let compressed: Vec<Vec<u8>> = present
            .iter()
            .map(|s| {
                ruzstd::encoding::compress_to_vec(
                    &s[..],
                    ruzstd::encoding::CompressionLevel::Fastest,
                )
            })
            .collect();
        for (c, s) in compressed.iter().zip(&present) {
            header.extend_from_slice(&(c.len() as u64).to_le_bytes());
            header.extend_from_slice(&(s.len() as u64).to_le_bytes());
        }
        for c in &compressed {
            header.extend_from_slice(c);
        }
        (header, want)
    }
}

#[test]
fn spz_of_every_version_decodes_as_its_description_says() {
    let splats = plain_splats(300);
    let dir = tempfile::tempdir().unwrap();
    for (version, degree, antialiased) in [
        (2, 3, false),
        (2, 0, true),
        (3, 2, false),
        (3, 1, true),
        (4, 3, true),
        (4, 0, false),
    ] {
        let (bytes, want) = spz_file(&splats, version, degree, antialiased);
        let path = dir.path().join(format!("v{version}_{degree}.spz"));
        std::fs::write(&path, &bytes).unwrap();
        let got = Splats::load(&path).unwrap();
        assert_eq!(got.source.version, Some(version));
        assert_eq!(got.source.antialiased, antialiased);
        let d = differences(&got, &want);
        assert!(
            d.iter().all(|v| *v <= 1e-6),
            "version {version}, degree {degree}: {d:?}"
        );
    }
}

#[test]
fn splat_records_decode_as_their_description_says() {
    let splats = plain_splats(200);
    let mut bytes = Vec::new();
    let mut want = Splats::with_capacity(200, SplatColor::Sh { degree: 0 }, SplatFormat::Splat);
    for p in &splats {
        for v in p.mean.to_array() {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let scale = p.log_scale.exp();
        for v in scale.to_array() {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let rgb = [0, 1, 2].map(|c| byte((0.5 + 0.282_094_8 * p.sh[c]) * 255.0));
        let a = byte(p.opacity * 255.0);
        bytes.extend_from_slice(&[rgb[0], rgb[1], rgb[2], a]);
        let q = p.rotation.map(|v| byte(v * 128.0 + 128.0));
        bytes.extend_from_slice(&q);
        let dc = rgb.map(|c| (f32::from(c) / 255.0 - 0.5) / 0.282_094_8);
        let rotation = q.map(|b| (f32::from(b) - 128.0) / 128.0);
        assert!(want.push_activated(p.mean, scale, rotation, f32::from(a) / 255.0, &dc));
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("w.splat");
    std::fs::write(&path, &bytes).unwrap();
    let got = Splats::load(&path).unwrap();
    let d = differences(&got, &want);
    assert!(d.iter().all(|v| *v <= 1e-6), "{d:?}");
}

/// Renders of the real SOG and of every fixture give finite, non-empty images; `nerfx info`
/// names each format.
#[test]
fn every_format_is_described_by_name() {
    for (name, says) in [
        ("subset_sh3.compressed.ply", "SuperSplat compressed PLY"),
        ("subset_sh3.sog", "PlayCanvas SOG, version 2"),
        ("subset_sh3.spz", "Niantic SPZ, version 4"),
        ("subset_sh3.v3.spz", "Niantic SPZ, version 3"),
        ("sjeongab_512.splat", "antimatter15 .splat"),
        ("subset_sh3.ply", "INRIA 3DGS PLY"),
    ] {
        let text = nerfx_core::field::describe(&data(name)).unwrap();
        assert!(text.contains(says) && text.contains("512 splats"), "{text}");
        assert!(
            text.contains("quantisation:") && text.contains("memory:"),
            "{text}"
        );
    }
}

// ---------------------------------------------------------------------------------------
// Bad input: a clear error naming the file and the element or image, never a panic.

/// The error loading `bytes` as the file `name` (in a fresh folder).
fn error_of(name: &str, bytes: &[u8]) -> String {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    match Splats::load(&path) {
        Ok(s) => panic!("{name} loaded {} splats", s.len()),
        Err(e) => e.to_string(),
    }
}

/// `sog` (a zip) with the entries named in `replace` replaced.
fn sog_with(sog: &[u8], replace: &[(&str, Vec<u8>)]) -> Vec<u8> {
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(sog)).unwrap();
    let mut out = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options =
        zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored);
    for i in 0..archive.len() {
        let mut entry = archive.by_index(i).unwrap();
        let name = entry.name().to_string();
        let mut data = Vec::new();
        std::io::Read::read_to_end(&mut entry, &mut data).unwrap();
        if let Some((_, new)) = replace.iter().find(|(n, _)| *n == name) {
            data = new.clone();
        }
        out.start_file(name, options).unwrap();
        out.write_all(&data).unwrap();
    }
    out.finish().unwrap().into_inner()
}

fn meta_of(sog: &[u8]) -> serde_json::Value {
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(sog)).unwrap();
    let mut text = String::new();
    std::io::Read::read_to_string(&mut archive.by_name("meta.json").unwrap(), &mut text).unwrap();
    serde_json::from_str(&text).unwrap()
}

#[test]
fn truncated_files_are_refused_naming_the_file_and_what_is_cut() {
    let cut = |name: &str, keep: f64| {
        let bytes = std::fs::read(data(name)).unwrap();
        let n = (bytes.len() as f64 * keep) as usize;
        let ext = name.rsplit('.').next().unwrap();
        error_of(&format!("cut.{ext}"), &bytes[..n])
    };
    let e = cut("sjeongab_512.splat", 0.5001);
    assert!(e.contains("cut.splat") && e.contains("32-byte"), "{e}");
    let e = cut("guitar_512.compressed.ply", 0.9);
    assert!(
        e.contains("cut.ply") && e.contains("element 'vertex'") && e.contains("truncated"),
        "{e}"
    );
    let e = cut("subset_sh3.v3.spz", 0.7);
    assert!(
        e.contains("cut.spz") && (e.contains("truncated") || e.contains("decompressed")),
        "{e}"
    );
    let e = cut("subset_sh3.spz", 0.7);
    assert!(e.contains("cut.spz") && e.contains("truncated"), "{e}");
    let e = cut("subset_sh3.sog", 0.7);
    assert!(e.contains("cut.sog"), "{e}");
}

#[test]
fn counts_larger_than_the_file_can_hold_are_refused_before_any_allocation() {
    // SPZ 4 claiming four billion splats in its 12 KB.
    let mut spz = std::fs::read(data("subset_sh3.spz")).unwrap();
    spz[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
    let e = error_of("huge.spz", &spz);
    assert!(
        e.contains("huge.spz") && e.contains("header") && e.contains("more than a file"),
        "{e}"
    );
    // The same inside a gzip stream.
    let (mut raw, _) = spz_file(&plain_splats(10), 3, 1, false);
    let mut inner = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(&raw[..]), &mut inner).unwrap();
    inner[8..12].copy_from_slice(&2_000_000_000u32.to_le_bytes());
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    gz.write_all(&inner).unwrap();
    raw = gz.finish().unwrap();
    let e = error_of("huge.spz", &raw);
    assert!(e.contains("more than a file"), "{e}");
    // A compressed PLY whose chunks do not cover its splats.
    let ply = std::fs::read(data("guitar_512.compressed.ply")).unwrap();
    let text =
        String::from_utf8_lossy(&ply).replacen("element vertex 512", "element vertex 900", 1);
    let e = error_of("more.ply", text.as_bytes());
    assert!(
        e.contains("more.ply") && e.contains("element 'vertex'"),
        "{e}"
    );
}

/// A gzip bomb: a small SPZ whose stream inflates to far more than its header's splats need.
/// Only what the count needs is inflated; the rest is never read.
#[test]
fn an_spz_gzip_bomb_inflates_only_what_its_count_needs() {
    let (file, want) = spz_file(&plain_splats(20), 3, 0, false);
    let mut inner = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(&file[..]), &mut inner).unwrap();
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    gz.write_all(&inner).unwrap();
    // 256 MiB of zeros after the splats.
    let zeros = vec![0u8; 1 << 20];
    for _ in 0..256 {
        gz.write_all(&zeros).unwrap();
    }
    let bomb = gz.finish().unwrap();
    assert!(bomb.len() < 1 << 20, "{} bytes", bomb.len());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bomb.spz");
    std::fs::write(&path, &bomb).unwrap();
    let got = Splats::load(&path).unwrap();
    assert_eq!(got.means, want.means);
}

#[test]
fn sog_images_and_meta_that_disagree_are_refused_naming_the_image() {
    let sog = std::fs::read(data("subset_sh3.sog")).unwrap();
    let mut meta = meta_of(&sog);
    meta["count"] = 100_000.into();
    let e = error_of(
        "more.sog",
        &sog_with(&sog, &[("meta.json", meta.to_string().into_bytes())]),
    );
    assert!(
        e.contains("more.sog") && e.contains("image 'means_l.webp'") && e.contains("fewer than"),
        "{e}"
    );

    // An image whose header claims 16383 × 16383 pixels for 512 splats: refused before decoding.
    let mut webp = b"RIFF\0\0\0\0WEBPVP8L\0\0\0\0\x2f".to_vec();
    let bits: u32 = 16382 | (16382 << 14) | (1 << 28);
    webp.extend_from_slice(&bits.to_le_bytes());
    webp.extend_from_slice(&[0u8; 64]);
    let chunk = (webp.len() - 20) as u32;
    webp[16..20].copy_from_slice(&chunk.to_le_bytes());
    let riff = (webp.len() - 8) as u32;
    webp[4..8].copy_from_slice(&riff.to_le_bytes());
    let e = error_of("big.sog", &sog_with(&sog, &[("quats.webp", webp)]));
    assert!(
        e.contains("big.sog") && e.contains("image 'quats.webp'") && e.contains("16383×16383"),
        "{e}"
    );

    let e = error_of(
        "junk.sog",
        &sog_with(&sog, &[("scales.webp", b"not an image".to_vec())]),
    );
    assert!(
        e.contains("image 'scales.webp'") && e.contains("WebP"),
        "{e}"
    );

    let mut meta = meta_of(&sog);
    meta["means"]["files"] = serde_json::json!(["means_l.webp"]);
    let e = error_of(
        "one.sog",
        &sog_with(&sog, &[("meta.json", meta.to_string().into_bytes())]),
    );
    assert!(e.contains("means.files"), "{e}");
}

#[test]
fn not_finite_or_absurd_quantisation_ranges_are_refused_naming_them() {
    // The compressed PLY's first chunk property, min_x, made NaN.
    let mut ply = std::fs::read(data("guitar_512.compressed.ply")).unwrap();
    let body = ply.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    ply[body..body + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    let e = error_of("nan.ply", &ply);
    assert!(
        e.contains("nan.ply") && e.contains("chunk 0") && e.contains("'min_x'"),
        "{e}"
    );
    // A log-scale range of 1e20.
    ply[body..body + 4].copy_from_slice(&0.0f32.to_le_bytes());
    ply[body + 24..body + 28].copy_from_slice(&1e20f32.to_le_bytes());
    let e = error_of("scale.ply", &ply);
    assert!(e.contains("'min_scale_x'"), "{e}");

    let sog = std::fs::read(data("subset_sh3.sog")).unwrap();
    let mut meta = meta_of(&sog);
    meta["means"]["mins"][1] = serde_json::json!(1e39);
    let e = error_of(
        "nan.sog",
        &sog_with(&sog, &[("meta.json", meta.to_string().into_bytes())]),
    );
    assert!(e.contains("nan.sog") && e.contains("means.mins"), "{e}");
    let mut meta = meta_of(&sog);
    meta["version"] = 7.into();
    let e = error_of(
        "v7.sog",
        &sog_with(&sog, &[("meta.json", meta.to_string().into_bytes())]),
    );
    assert!(e.contains("SOG version 7"), "{e}");
}

// ---------------------------------------------------------------------------------------
// Everywhere a splat file goes.

/// The splat instances of the scene `path` names (a scene file or one splat file), placed.
fn placed(path: &Path) -> Vec<SplatInstance> {
    let scene = nerfx_core::scene::SceneDesc::for_path(path)
        .and_then(|d| d.load())
        .and_then(|l| l.place(DMat4::IDENTITY, &|_| Ok(DMat4::IDENTITY)))
        .unwrap();
    scene.splats().cloned().collect()
}

#[test]
fn scenes_take_every_format_with_axes_and_the_antialiased_mode() {
    let dir = tempfile::tempdir().unwrap();
    // One file on its own, as the NeRF Render node's file parameter and the command line
    // take it: every format, and a SOG folder by its meta.json or itself.
    let sog_dir = dir.path().join("scan_sog");
    std::fs::create_dir(&sog_dir).unwrap();
    let sog = std::fs::read(data("subset_sh3.sog")).unwrap();
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(&sog[..])).unwrap();
    archive.extract(&sog_dir).unwrap();
    for path in [
        data("subset_sh3.compressed.ply"),
        data("subset_sh3.sog"),
        data("subset_sh3.spz"),
        data("sjeongab_512.splat"),
        sog_dir.join("meta.json"),
        sog_dir.clone(),
    ] {
        let splats = placed(&path);
        assert_eq!(splats.len(), 1, "{}", path.display());
        assert_eq!(splats[0].splats().len(), 512, "{}", path.display());
    }
    let from_folder = placed(&sog_dir);
    let from_zip = placed(&data("subset_sh3.sog"));
    assert_eq!(from_folder[0].splats().means, from_zip[0].splats().means);

    // A scene: "axes": "rub" brings splat-transform's SPZ back into its PLY's frame; the
    // antialiased mode follows the file unless the scene says otherwise.
    let source = Splats::load(&data("subset_sh3.ply")).unwrap();
    let (antialiased_spz, _) = spz_file(&plain_splats(8), 3, 1, true);
    std::fs::write(dir.path().join("aa.spz"), antialiased_spz).unwrap();
    let mut mip_ply = std::fs::read(data("subset_sh3.ply")).unwrap();
    let at = mip_ply.windows(7).position(|w| w == b"element").unwrap();
    mip_ply.splice(at..at, b"comment SplatRenderMode: mip\n".iter().copied());
    std::fs::write(dir.path().join("mip.ply"), mip_ply).unwrap();
    let scene = serde_json::json!({ "instances": [
        { "name": "rub", "field": { "splats": {
            "path": data("subset_sh3.spz"), "axes": "rub" } } },
        { "name": "aa", "field": { "splats": { "path": "aa.spz" } } },
        { "name": "aa off", "field": { "splats": { "path": "aa.spz", "antialiased": false } } },
        { "name": "mip", "field": { "splats": { "path": "mip.ply" } } },
        { "name": "plain", "field": { "splats": { "path": data("subset_sh3.ply") } } },
        { "name": "forced", "field": { "splats": {
            "path": data("subset_sh3.ply"), "antialiased": true } } } ] });
    let path = dir.path().join("scene.json");
    std::fs::write(&path, scene.to_string()).unwrap();
    let splats = placed(&path);
    let worst = splats[0]
        .splats()
        .means
        .iter()
        .zip(&source.means)
        .map(|(a, b)| (*a - *b).abs().max_element())
        .fold(0.0f32, f32::max);
    assert!(worst <= 1.0 / 4096.0, "{worst}");
    let modes: Vec<bool> = splats.iter().map(|s| s.antialiased()).collect();
    assert_eq!(modes, [false, true, false, true, false, true]);
    let text = nerfx_core::field::describe(&dir.path().join("mip.ply")).unwrap();
    assert!(
        text.contains("antialiased (mip-splatting) mode: yes"),
        "{text}"
    );
}

/// A lossless RGBA WebP of `pixels` (4 bytes each) in a `width`-wide image, padded.
fn webp(pixels: &[u8], width: usize) -> Vec<u8> {
    let height = (pixels.len() / 4).div_ceil(width).max(1);
    let mut data = pixels.to_vec();
    data.resize(width * height * 4, 0);
    let mut out = Vec::new();
    image_webp::WebPEncoder::new(&mut out)
        .encode(
            &data,
            width as u32,
            height as u32,
            image_webp::ColorType::Rgba8,
        )
        .unwrap();
    out
}

/// SOG version 1 (a folder: `meta.json` with per-channel ranges, WebP images), written from
/// its description, with SH degree 1 through a palette of one entry per splat; and the splats
/// the description decodes it to.
fn sog_v1_folder(dir: &Path, splats: &[Plain]) -> Splats {
    let n = splats.len();
    let width = 16;
    let log = |v: f32| v.signum() * (v.abs() + 1.0).ln();
    let range = |values: &mut dyn Iterator<Item = f32>| {
        values.fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        })
    };
    let ranges3 = |f: &dyn Fn(&Plain) -> Vec3| {
        let r: Vec<(f32, f32)> = (0..3)
            .map(|k| range(&mut splats.iter().map(|p| f(p)[k])))
            .collect();
        ([r[0].0, r[1].0, r[2].0], [r[0].1, r[1].1, r[2].1])
    };
    let (mean_lo, mean_hi) = ranges3(&|p| Vec3::new(log(p.mean.x), log(p.mean.y), log(p.mean.z)));
    let (scale_lo, scale_hi) = ranges3(&|p| p.log_scale);
    let (dc_lo, dc_hi) = ranges3(&|p| Vec3::new(p.sh[0], p.sh[1], p.sh[2]));
    let logit = |o: f32| (o / (1.0 - o)).ln();
    let (op_lo, op_hi) = range(&mut splats.iter().map(|p| logit(p.opacity)));
    let (sh_lo, sh_hi) = range(&mut splats.iter().flat_map(|p| p.sh[3..12].iter().copied()));
    let quantise = |v: f32, lo: f32, hi: f32, steps: f32| {
        if hi > lo {
            ((v - lo) / (hi - lo) * steps).round()
        } else {
            0.0
        }
    };
    let lerp = |lo: f32, hi: f32, b: f32, steps: f32| lo + (hi - lo) * (b / steps);
    let (mut means_l, mut means_u, mut quats, mut scales, mut sh0, mut labels, mut centroids) =
        (vec![], vec![], vec![], vec![], vec![], vec![], vec![]);
    let mut want = Splats::with_capacity(n, SplatColor::Sh { degree: 1 }, SplatFormat::Sog);
    for (i, p) in splats.iter().enumerate() {
        let mut mean = Vec3::ZERO;
        for k in 0..3 {
            let v = quantise(log(p.mean[k]), mean_lo[k], mean_hi[k], 65535.0) as u16;
            means_l.push(v as u8);
            means_u.push((v >> 8) as u8);
            let t = lerp(mean_lo[k], mean_hi[k], f32::from(v), 65535.0);
            mean[k] = t.signum() * (t.abs().exp() - 1.0);
        }
        means_l.push(255);
        means_u.push(255);
        // Smallest three of w x y z, the largest made positive, each (b/255·2 − 1)/√2.
        let q = p.rotation;
        let largest = (0..4)
            .max_by(|&a, &b| q[a].abs().total_cmp(&q[b].abs()))
            .unwrap();
        let sign = q[largest].signum();
        let mut rotation = [0.0f32; 4];
        let mut sum = 0.0;
        for (k, v) in q.iter().enumerate() {
            if k != largest {
                let b = ((v * sign * std::f32::consts::SQRT_2 + 1.0) / 2.0 * 255.0).round();
                quats.push(b as u8);
                rotation[k] = (b / 255.0 * 2.0 - 1.0) / std::f32::consts::SQRT_2;
                sum += rotation[k] * rotation[k];
            }
        }
        quats.push(252 + largest as u8);
        rotation[largest] = (1.0 - sum).max(0.0).sqrt();
        let mut log_scale = Vec3::ZERO;
        for k in 0..3 {
            let b = quantise(p.log_scale[k], scale_lo[k], scale_hi[k], 255.0);
            scales.push(b as u8);
            log_scale[k] = lerp(scale_lo[k], scale_hi[k], b, 255.0);
        }
        scales.push(255);
        let mut coeffs = [0.0f32; 12];
        for k in 0..3 {
            let b = quantise(p.sh[k], dc_lo[k], dc_hi[k], 255.0);
            sh0.push(b as u8);
            coeffs[k] = lerp(dc_lo[k], dc_hi[k], b, 255.0);
        }
        let b = quantise(logit(p.opacity), op_lo, op_hi, 255.0);
        sh0.push(b as u8);
        let opacity = 1.0 / (1.0 + (-lerp(op_lo, op_hi, b, 255.0)).exp());
        // Palette entry i: three pixels (one a coefficient), r g b the channels.
        labels.extend_from_slice(&[(i & 255) as u8, (i >> 8) as u8, 0, 255]);
        for j in 0..3 {
            for c in 0..3 {
                let b = quantise(p.sh[(j + 1) * 3 + c], sh_lo, sh_hi, 255.0);
                centroids.push(b as u8);
                coeffs[(j + 1) * 3 + c] = lerp(sh_lo, sh_hi, b, 255.0);
            }
            centroids.push(255);
        }
        assert!(want.push_activated(mean, log_scale.exp(), rotation, opacity, &coeffs));
    }
    for (name, pixels, w) in [
        ("means_l.webp", &means_l, width),
        ("means_u.webp", &means_u, width),
        ("quats.webp", &quats, width),
        ("scales.webp", &scales, width),
        ("sh0.webp", &sh0, width),
        ("shN_labels.webp", &labels, width),
        ("shN_centroids.webp", &centroids, 192),
    ] {
        std::fs::write(dir.join(name), webp(pixels, w)).unwrap();
    }
    let meta = serde_json::json!({
        "means": { "shape": [n, 3], "mins": mean_lo, "maxs": mean_hi,
                   "files": ["means_l.webp", "means_u.webp"] },
        "scales": { "mins": scale_lo, "maxs": scale_hi, "files": ["scales.webp"] },
        "quats": { "files": ["quats.webp"] },
        "sh0": { "mins": [dc_lo[0], dc_lo[1], dc_lo[2], op_lo],
                 "maxs": [dc_hi[0], dc_hi[1], dc_hi[2], op_hi], "files": ["sh0.webp"] },
        "shN": { "mins": sh_lo, "maxs": sh_hi,
                 "files": ["shN_centroids.webp", "shN_labels.webp"] },
    });
    std::fs::write(dir.join("meta.json"), meta.to_string()).unwrap();
    want
}

#[test]
fn a_sog_version_1_folder_decodes_as_its_description_says() {
    let dir = tempfile::tempdir().unwrap();
    let want = sog_v1_folder(dir.path(), &plain_splats(100));
    for path in [dir.path().join("meta.json"), dir.path().to_path_buf()] {
        let got = Splats::load(&path).unwrap();
        assert_eq!(got.source.version, Some(1));
        let d = differences(&got, &want);
        println!("SOG 1: {d:?}");
        assert!(d[0] <= 1e-5 && d[1] <= 1e-5 && d[2] <= 1e-6, "{d:?}");
        assert!(d[3] <= 1e-6 && d[4] <= 1e-5, "{d:?}");
    }
}

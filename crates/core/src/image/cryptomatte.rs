//! Cryptomatte (Psyop's specification, version 1.2): per-object mattes a compositor picks by
//! clicking, as ID–coverage pairs per pixel.
//!
//! - An object's ID is the MurmurHash3 (x86, 32 bits, seed 0) of its name's UTF-8 bytes,
//!   stored as the 32-bit float with those bits (`uint32_to_float32`); a hash whose exponent
//!   bits are all 0 or all 1 (a denormal, an infinity or a NaN) has the lowest exponent bit
//!   flipped first.
//! - A pixel's pairs are sorted by coverage, largest first, and laid two to a layer:
//!   `CryptoObject00.R` = ID of rank 0, `.G` its coverage, `.B` = ID of rank 1, `.A` its
//!   coverage, then `CryptoObject01` for ranks 2 and 3, … Ranks nothing covers hold 0, 0.
//! - The header says, under `cryptomatte/<key>/` (`key`: the first 7 hex digits of the
//!   layer name's hash): `name` (the layer name), `hash` (`MurmurHash3_32`), `conversion`
//!   (`uint32_to_float32`) and `manifest`, a JSON object from each name to its ID's bits in
//!   8 hex digits.
//!
//! Worked number: `"bunny"` hashes to `0x13851a76`, a normal float (exponent 39), so its ID
//! is `f32::from_bits(0x13851a76)` ≈ 3.36e-27 and its manifest entry `"13851a76"`.

use crate::error::{Error, Result};
use crate::image::{Plane, Planes};

/// The layer name nerfx writes object mattes under.
pub const OBJECT_LAYER: &str = "CryptoObject";

/// Ranks (ID–coverage pairs per pixel) written by default: three layers.
pub const DEFAULT_RANKS: usize = 6;

/// Most ranks: far more than overlap in a pixel of any real comp.
pub const MAX_RANKS: usize = 64;

/// The MurmurHash3 (x86, 32 bits, seed 0) of `name`'s UTF-8 bytes.
pub(crate) fn name_hash(name: &str) -> u32 {
    mur3::murmurhash3_x86_32(name.as_bytes(), 0)
}

/// The bits of the ID of `name`: its hash, with the lowest exponent bit flipped where the
/// exponent is 0 or 255 (so the float is finite and normal).
pub(crate) fn id_bits(name: &str) -> u32 {
    let hash = name_hash(name);
    let exponent = (hash >> 23) & 0xff;
    if exponent == 0 || exponent == 0xff {
        hash ^ (1 << 23)
    } else {
        hash
    }
}

/// The ID of `name` as the float the matte channels hold.
///
/// ```
/// assert_eq!(nerfx_core::image::cryptomatte::object_id("bunny").to_bits(), 0x13851a76);
/// ```
pub fn object_id(name: &str) -> f32 {
    f32::from_bits(id_bits(name))
}

/// The manifest: a JSON object from each name to its ID's bits (8 lowercase hex digits).
pub(crate) fn manifest(names: &[&str]) -> String {
    let map: serde_json::Map<String, serde_json::Value> = names
        .iter()
        .map(|n| (n.to_string(), format!("{:08x}", id_bits(n)).into()))
        .collect();
    serde_json::Value::Object(map).to_string()
}

/// The header entries of the layer `layer` holding the objects `names`.
pub fn header_entries(layer: &str, names: &[&str]) -> Vec<(String, String)> {
    let key = &format!("{:08x}", name_hash(layer))[..7];
    let entry = |what: &str, value: String| (format!("cryptomatte/{key}/{what}"), value);
    vec![
        entry("name", layer.to_string()),
        entry("hash", "MurmurHash3_32".into()),
        entry("conversion", "uint32_to_float32".into()),
        entry("manifest", manifest(names)),
    ]
}

/// The matte layers (`layer00`, `layer01`, …, each as RGBA planes) of `ranks` ranks, from
/// each object's coverage plane: `coverage[i]` is the share of each pixel's opacity that
/// `names[i]` covers. Objects of the same name are one object (their coverages add).
///
/// Errors: [`Error::Invalid`] for no ranks or more than [`MAX_RANKS`], or coverage planes
/// that are not one per name or not all of one size.
pub fn layers(
    layer: &str,
    names: &[&str],
    coverage: &[Plane],
    ranks: usize,
) -> Result<Vec<(String, Planes)>> {
    if ranks == 0 || ranks > MAX_RANKS {
        return Err(Error::invalid(
            "cryptomatte ranks",
            format!("{ranks}; expected 1 to {MAX_RANKS}"),
        ));
    }
    if coverage.len() != names.len() {
        return Err(Error::invalid(
            "cryptomatte",
            format!(
                "{} coverage planes for {} names",
                coverage.len(),
                names.len()
            ),
        ));
    }
    let (w, h) = coverage.first().map_or((1, 1), |p| (p.width, p.height));
    if coverage
        .iter()
        .any(|p| (p.width, p.height) != (w, h) || p.data.len() != w as usize * h as usize)
    {
        return Err(Error::invalid(
            "cryptomatte",
            "coverage planes of different sizes",
        ));
    }
    // One object per distinct name, in first-seen order.
    let mut objects: Vec<(&str, f32, Vec<usize>)> = Vec::new();
    for (i, name) in names.iter().enumerate() {
        match objects.iter_mut().find(|(n, ..)| n == name) {
            Some((.., planes)) => planes.push(i),
            None => objects.push((name, object_id(name), vec![i])),
        }
    }
    let count = ranks.div_ceil(2);
    let mut out: Vec<[Plane; 4]> = (0..count)
        .map(|_| std::array::from_fn(|_| Plane::filled(w, h, 0.0)))
        .collect();
    let mut pixel: Vec<(f32, f32)> = Vec::with_capacity(objects.len());
    for p in 0..w as usize * h as usize {
        pixel.clear();
        for (_, id, planes) in &objects {
            let c: f32 = planes.iter().map(|&i| coverage[i].data[p]).sum();
            if c > 0.0 {
                pixel.push((*id, c));
            }
        }
        // Largest coverage first; ties by ID, so the order never depends on the scene's.
        pixel.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.total_cmp(&b.0)));
        for (rank, &(id, c)) in pixel.iter().take(ranks).enumerate() {
            let planes = &mut out[rank / 2];
            let k = 2 * (rank % 2);
            planes[k].data[p] = id;
            planes[k + 1].data[p] = c;
        }
    }
    Ok(out
        .into_iter()
        .enumerate()
        .map(|(i, [r, g, b, a])| {
            (
                format!("{layer}{i:02}"),
                Planes {
                    width: w,
                    height: h,
                    rgb: Some([r, g, b]),
                    alpha: Some(a),
                    depth_z: None,
                    depth_ray: None,
                    depth_median: None,
                },
            )
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_are_normal_floats_and_known_hashes() {
        // Reference values of MurmurHash3_x86_32 (seed 0).
        assert_eq!(name_hash(""), 0);
        assert_eq!(name_hash("hello"), 0x248b_fa47);
        assert_eq!(name_hash("bunny"), 0x1385_1a76);
        // An exponent of 0 or 255 is moved off by one bit: every ID is a normal float.
        for i in 0..20_000 {
            let name = format!("object {i}");
            let id = object_id(&name);
            assert!(id.is_normal(), "{name}: {id}");
            let (h, b) = (name_hash(&name), id_bits(&name));
            assert!(h == b || h ^ b == 1 << 23, "{name}");
        }
    }

    #[test]
    fn pairs_are_ranked_by_coverage_two_to_a_layer() {
        let plane = |v: &[f32]| Plane {
            width: 2,
            height: 1,
            data: v.to_vec(),
        };
        let names = ["a", "b", "c", "a"];
        let coverage = [
            plane(&[0.1, 0.0]),
            plane(&[0.5, 0.0]),
            plane(&[0.3, 0.2]),
            plane(&[0.15, 0.0]),
        ];
        let layers = layers("CryptoObject", &names, &coverage, 3).unwrap();
        assert_eq!(layers.len(), 2);
        assert_eq!(layers[0].0, "CryptoObject00");
        let [r, g, b] = layers[0].1.rgb.as_ref().unwrap();
        let a = layers[0].1.alpha.as_ref().unwrap();
        // Pixel 0: b 0.5, c 0.3, a 0.25 (two instances named a).
        assert_eq!((r.data[0], g.data[0]), (object_id("b"), 0.5));
        assert_eq!((b.data[0], a.data[0]), (object_id("c"), 0.3));
        let second = &layers[1].1;
        assert_eq!(second.rgb.as_ref().unwrap()[0].data[0], object_id("a"));
        assert_eq!(second.rgb.as_ref().unwrap()[1].data[0], 0.25);
        // Rank 3 is not written (three ranks), and pixel 1 has one object.
        assert_eq!(second.alpha.as_ref().unwrap().data[0], 0.0);
        assert_eq!(
            (r.data[1], g.data[1], b.data[1]),
            (object_id("c"), 0.2, 0.0)
        );
        assert!(super::layers("x", &names, &coverage[..2], 6).is_err());
        assert!(super::layers("x", &names, &coverage, 0).is_err());
    }

    #[test]
    fn the_header_names_the_layer_under_its_key() {
        let entries = header_entries("CryptoObject", &["bunny"]);
        let key = &format!("{:08x}", name_hash("CryptoObject"))[..7];
        assert_eq!(
            entries[0],
            (format!("cryptomatte/{key}/name"), "CryptoObject".into())
        );
        assert_eq!(entries[1].1, "MurmurHash3_32");
        assert_eq!(entries[2].1, "uint32_to_float32");
        assert_eq!(entries[3].1, r#"{"bunny":"13851a76"}"#);
    }
}

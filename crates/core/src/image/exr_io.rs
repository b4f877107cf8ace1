//! OpenEXR output of render planes, and a small reader for checking and comparing them.
//!
//! One single-part scanline file, 32-bit float, ZIP compression (lossless, 16 lines per block),
//! because every compositor reads that and f32 keeps depth exact. Channel names follow the
//! conventions compositors use to sort channels into layers (Nuke and Natron split a name at
//! its last `.` into `layer.channel`):
//!
//! | plane                 | channel        | layer in a compositor |
//! |-----------------------|----------------|-----------------------|
//! | `rgb` (premultiplied) | `R`, `G`, `B`  | `rgba`                |
//! | `alpha` (Σ wᵢ)        | `A`            | `rgba`                |
//! | `depth_z`             | `Z`            | `depth` (Nuke `depth.Z`) |
//! | `depth_ray`           | `depth.ray`    | `depth`               |
//! | `depth_median`        | `depth.median` | `depth`               |
//!
//! The accumulation *is* the alpha (EXR colour is premultiplied, as the render's is), so it is
//! not written twice. Only the planes present are written.
//!
//! Depth where nothing was hit is `inf` in the planes; many compositing operations turn `inf`
//! into NaN (`inf·0`, `inf − inf`), so it is written as [`BACKGROUND_DEPTH`] = 10¹⁰ instead,
//! the value Blender writes for the background in its Z pass. Depth merges against Blender
//! renders then see the same "far" on both sides.

use std::path::Path;

use exr::meta::attribute::{AttributeValue, Chromaticities, Text};
use exr::prelude::{
    AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, SmallVec, Vec2,
    WritableImage,
};

use crate::error::{number, Error, Result};
use crate::image::{CameraMatrices, ExrHeader, OutputColorSpace, Plane, Planes};

/// Depth written where nothing was hit (the plane holds `inf` there): Blender's background
/// value in its Z pass.
pub const BACKGROUND_DEPTH: f32 = 1.0e10;

/// Writes the present `planes` to `path` as a scanline f32 EXR (channel names in the module
/// docs), linear Rec.709 with square pixels.
///
/// Errors: [`Error::Invalid`] when no plane is present, the image is empty, or a plane's size
/// disagrees with `planes`; [`Error::Io`] naming `path` when the file cannot be written.
pub fn write_exr(path: &Path, planes: &Planes) -> Result<()> {
    write_exr_layers(path, planes, &[], &ExrHeader::default())
}

/// Writes `main` as [`write_exr`] does plus each of `layers` under its name, as channels
/// `name.R`, `name.G`, `name.B`, `name.A` (`name.Z`, … for depths): one file a compositor
/// splits into layers. Every layer must have `main`'s size. `header` says what else the file
/// tells a compositor ([`ExrHeader`]): the pixel aspect (width over height of a pixel, e.g. 2
/// for an anamorphic shot), the `chromaticities` of its colour space (always written), the
/// camera's `worldToCamera` and `worldToNDC`, `framesPerSecond` and text entries.
pub fn write_exr_layers(
    path: &Path,
    main: &Planes,
    layers: &[(&str, &Planes)],
    header: &ExrHeader,
) -> Result<()> {
    let pixel_aspect = header.pixel_aspect;
    if !(pixel_aspect.is_finite() && pixel_aspect > 0.0) {
        return Err(Error::invalid(
            format!("EXR {}: pixel aspect", path.display()),
            format!("expected a positive number, got {}", number(pixel_aspect)),
        ));
    }
    let mut channels = channels_of(main, "")?;
    for (name, planes) in layers {
        if (planes.width, planes.height) != (main.width, main.height) {
            return Err(Error::invalid(
                format!("EXR output: layer {name}"),
                format!(
                    "is {}×{}, the image {}×{}",
                    planes.width, planes.height, main.width, main.height
                ),
            ));
        }
        channels.extend(channels_of(planes, &format!("{name}."))?);
    }
    write_channels(path, (main.width, main.height), channels, header)
}

/// Writes named f32 channels of one size to `path` as [`write_exr_layers`] writes its planes
/// (same header, compression and channel order), so that channels read back from nerfx's own
/// files (see [`read_exr_image`]) and joined are written as the whole image would have been.
///
/// Errors: [`Error::Invalid`] when there is no channel, a channel's size differs from
/// `width`×`height`, or a sample is NaN; [`Error::Io`] naming `path`.
pub fn write_exr_channels(
    path: &Path,
    (width, height): (u32, u32),
    channels: &[(String, Plane)],
    header: &ExrHeader,
) -> Result<()> {
    let pixel_aspect = header.pixel_aspect;
    if channels.is_empty() || width == 0 || height == 0 {
        return Err(Error::invalid(
            format!("EXR {}", path.display()),
            "no channel or an empty image to write",
        ));
    }
    if !(pixel_aspect.is_finite() && pixel_aspect > 0.0) {
        return Err(Error::invalid(
            format!("EXR {}: pixel aspect", path.display()),
            format!("expected a positive number, got {pixel_aspect}"),
        ));
    }
    let expected = width as usize * height as usize;
    let mut any = SmallVec::new();
    for (name, plane) in channels {
        if (plane.width, plane.height) != (width, height) || plane.data.len() != expected {
            return Err(Error::invalid(
                format!("EXR {}: channel {name}", path.display()),
                format!(
                    "is {}×{}, the image {width}×{height}",
                    plane.width, plane.height
                ),
            ));
        }
        if let Some(i) = plane.data.iter().position(|v| v.is_nan()) {
            return Err(Error::invalid(
                format!("EXR {}: channel {name}", path.display()),
                format!(
                    "pixel ({}, {}) is NaN: not written",
                    i % width as usize,
                    i / width as usize
                ),
            ));
        }
        any.push(AnyChannel::new(
            name.as_str(),
            FlatSamples::F32(plane.data.clone()),
        ));
    }
    write_channels(path, (width, height), any, header)
}

/// The one place an image's header and encoding are decided.
fn write_channels(
    path: &Path,
    (width, height): (u32, u32),
    channels: SmallVec<[AnyChannel<FlatSamples>; 4]>,
    header: &ExrHeader,
) -> Result<()> {
    let layer = Layer::new(
        (width as usize, height as usize),
        layer_attributes(header),
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(channels),
    );
    let mut image = Image::from_layer(layer);
    image.attributes.pixel_aspect = header.pixel_aspect as f32;
    image.attributes.chromaticities = Some(chromaticities(header.color_space));
    crate::output::replace_file(path, |temp| {
        image.write().to_file(temp).map_err(|e| match e {
            exr::error::Error::Io(source) => Error::io(path, source),
            other => Error::invalid(format!("EXR {}", path.display()), other.to_string()),
        })
    })
}

/// The header's layer attributes: software, camera, frame rate and text entries.
fn layer_attributes(header: &ExrHeader) -> LayerAttributes {
    let mut attributes = LayerAttributes {
        software_name: Some("nerfx".into()),
        frames_per_second: header.frames_per_second,
        ..LayerAttributes::default()
    };
    if let Some(camera) = &header.camera {
        attributes.world_to_camera = Some(camera.world_to_camera);
        attributes.world_to_normalized_device = camera.world_to_ndc;
    }
    // Stored as their UTF-8 bytes, as OpenEXR's own library stores a string (a path may
    // hold any character).
    let text = |s: &str| Text::from_slice_unchecked(s.as_bytes());
    for (key, value) in &header.entries {
        attributes
            .other
            .insert(text(key), AttributeValue::Text(text(value)));
    }
    attributes
}

/// The `chromaticities` attribute of `space`.
fn chromaticities(space: OutputColorSpace) -> Chromaticities {
    let c = space.chromaticities();
    let xy = |[x, y]: [f64; 2]| Vec2(x as f32, y as f32);
    Chromaticities {
        red: xy(c.red),
        green: xy(c.green),
        blue: xy(c.blue),
        white: xy(c.white),
    }
}

/// Reads every channel of every layer of the EXR at `path` as f32 planes (f16 and u32 samples
/// are converted), in the file's order. Channels of a named part are prefixed with
/// `part.`; the names of a single-part file are as stored (`R`, `depth.ray`, ...).
///
/// Errors: [`Error::Io`] when the file cannot be read, [`Error::Format`] when it is not a flat
/// (non-deep) EXR this reader understands.
pub fn read_exr_channels(path: &Path) -> Result<Vec<(String, Plane)>> {
    read_exr_image(path).map(|(channels, _)| channels)
}

/// [`read_exr_channels`], and what the header says of the image ([`ExrHeader`]): pixel
/// aspect, camera, frame rate, the text entries, and the colour space (from its
/// `nerfx/colorspace` entry, else linear Rec.709), so that an image nerfx wrote can be
/// written again as it was.
pub fn read_exr_image(path: &Path) -> Result<(Vec<(String, Plane)>, ExrHeader)> {
    let image = exr::prelude::read_all_flat_layers_from_file(path).map_err(|e| match e {
        exr::error::Error::Io(source) => Error::io(path, source),
        other => Error::format(path, "", other.to_string()),
    })?;
    let header = header_of(&image);
    let mut out = Vec::new();
    for layer in image.layer_data {
        let prefix = match &layer.attributes.layer_name {
            Some(name) => format!("{name}."),
            None => String::new(),
        };
        for channel in layer.channel_data.list {
            let data = match channel.sample_data {
                FlatSamples::F16(v) => v.into_iter().map(|h| h.to_f32()).collect(),
                FlatSamples::F32(v) => v,
                FlatSamples::U32(v) => v.into_iter().map(|u| u as f32).collect(),
            };
            let plane = Plane {
                width: layer.size.0 as u32,
                height: layer.size.1 as u32,
                data,
            };
            out.push((format!("{prefix}{}", channel.name), plane));
        }
    }
    Ok((out, header))
}

/// The header entries of `image` that [`write_exr_layers`] writes.
fn header_of(image: &exr::image::FlatImage) -> ExrHeader {
    let mut header = ExrHeader {
        pixel_aspect: f64::from(image.attributes.pixel_aspect),
        ..ExrHeader::default()
    };
    let Some(first) = image.layer_data.first().map(|layer| &layer.attributes) else {
        return header;
    };
    header.camera = first.world_to_camera.map(|world_to_camera| CameraMatrices {
        world_to_camera,
        world_to_ndc: first.world_to_normalized_device,
    });
    header.frames_per_second = first.frames_per_second;
    let mut entries: Vec<(String, String)> = first
        .other
        .iter()
        .filter_map(|(key, value)| match value {
            AttributeValue::Text(text) => Some((key.to_string(), text.to_string())),
            _ => None,
        })
        .collect();
    entries.sort();
    header.color_space = entries
        .iter()
        .find(|(key, _)| key == "nerfx/colorspace")
        .and_then(|(_, name)| OutputColorSpace::parse(name, "nerfx/colorspace").ok())
        .unwrap_or_default();
    header.entries = entries;
    header
}

/// The EXR channels for the present planes, names prefixed by `prefix`, checked against the
/// image size.
fn channels_of(planes: &Planes, prefix: &str) -> Result<SmallVec<[AnyChannel<FlatSamples>; 4]>> {
    if planes.width == 0 || planes.height == 0 {
        return Err(Error::invalid(
            "EXR output",
            format!("empty image {}×{}", planes.width, planes.height),
        ));
    }
    let mut named: Vec<(&str, &Plane, bool)> = Vec::new();
    if let Some([r, g, b]) = &planes.rgb {
        named.extend([("R", r, false), ("G", g, false), ("B", b, false)]);
    }
    let depths = [
        ("Z", &planes.depth_z),
        ("depth.ray", &planes.depth_ray),
        ("depth.median", &planes.depth_median),
    ];
    named.extend(planes.alpha.iter().map(|a| ("A", a, false)));
    named.extend(
        depths
            .iter()
            .filter_map(|(name, plane)| plane.as_ref().map(|p| (*name, p, true))),
    );
    if named.is_empty() {
        return Err(Error::invalid("EXR output", "no plane to write"));
    }
    let expected = planes.width as usize * planes.height as usize;
    named
        .into_iter()
        .map(|(name, plane, is_depth)| {
            if plane.width != planes.width
                || plane.height != planes.height
                || plane.data.len() != expected
            {
                return Err(Error::invalid(
                    format!("EXR output: channel {name}"),
                    format!(
                        "plane is {}×{} with {} samples, image is {}×{}",
                        plane.width,
                        plane.height,
                        plane.data.len(),
                        planes.width,
                        planes.height
                    ),
                ));
            }
            // Colour and alpha must be finite; depth may be +inf (nothing hit).
            let bad = plane.data.iter().position(|&v| {
                v.is_nan() || (!is_depth && v.is_infinite()) || v == f32::NEG_INFINITY
            });
            if let Some(i) = bad {
                return Err(Error::invalid(
                    format!("EXR output: channel {prefix}{name}"),
                    format!(
                        "pixel ({}, {}) is {}: not written",
                        i % planes.width as usize,
                        i / planes.width as usize,
                        plane.data[i]
                    ),
                ));
            }
            let data = if is_depth {
                plane
                    .data
                    .iter()
                    .map(|&d| {
                        if d == f32::INFINITY {
                            BACKGROUND_DEPTH
                        } else {
                            d
                        }
                    })
                    .collect()
            } else {
                plane.data.clone()
            };
            Ok(AnyChannel::new(
                format!("{prefix}{name}").as_str(),
                FlatSamples::F32(data),
            ))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    /// A unique path in the temp directory, removed on drop.
    struct TempFile(PathBuf);

    impl TempFile {
        fn new(tag: &str) -> Self {
            let nanos = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_nanos())
                .unwrap_or(0);
            TempFile(std::env::temp_dir().join(format!(
                "nerfx-exr-{tag}-{}-{nanos}.exr",
                std::process::id()
            )))
        }
    }

    impl Drop for TempFile {
        fn drop(&mut self) {
            let _ = std::fs::remove_file(&self.0);
        }
    }

    /// A plane whose samples are a distinct, non-trivial function of the pixel and `seed`
    /// (negative, tiny and large values included, so bit exactness is really tested).
    fn pattern(w: u32, h: u32, seed: f32) -> Plane {
        let data = (0..w * h)
            .map(|i| ((i as f32 * 0.731 + seed).sin() * 3.7).powi(3) * 1.0e-3_f32.powf(seed))
            .collect();
        Plane {
            width: w,
            height: h,
            data,
        }
    }

    fn find<'a>(channels: &'a [(String, Plane)], name: &str) -> &'a Plane {
        &channels
            .iter()
            .find(|(n, _)| n == name)
            .unwrap_or_else(|| panic!("channel {name} missing"))
            .1
    }

    #[test]
    fn round_trip_is_bit_exact_and_names_channels() {
        let (w, h) = (37, 23);
        let mut depth_z = pattern(w, h, 0.4);
        depth_z.data[5] = f32::INFINITY;
        let planes = Planes {
            width: w,
            height: h,
            rgb: Some([pattern(w, h, 0.1), pattern(w, h, 0.2), pattern(w, h, 0.3)]),
            alpha: Some(pattern(w, h, 0.5)),
            depth_z: Some(depth_z.clone()),
            depth_ray: Some(pattern(w, h, 0.6)),
            depth_median: Some(pattern(w, h, 0.7)),
        };
        let file = TempFile::new("roundtrip");
        write_exr(&file.0, &planes).unwrap();
        let channels = read_exr_channels(&file.0).unwrap();

        let mut names: Vec<&str> = channels.iter().map(|(n, _)| n.as_str()).collect();
        names.sort_unstable();
        assert_eq!(
            names,
            ["A", "B", "G", "R", "Z", "depth.median", "depth.ray"]
        );
        let [r, g, b] = planes.rgb.as_ref().unwrap();
        let expect: [(&str, &Plane); 6] = [
            ("R", r),
            ("G", g),
            ("B", b),
            ("A", planes.alpha.as_ref().unwrap()),
            ("depth.ray", planes.depth_ray.as_ref().unwrap()),
            ("depth.median", planes.depth_median.as_ref().unwrap()),
        ];
        for (name, want) in expect {
            let got = find(&channels, name);
            assert_eq!((got.width, got.height), (w, h), "{name}");
            let same = got
                .data
                .iter()
                .zip(&want.data)
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same, "channel {name} differs");
        }
        // Z: bit exact except the background sample, which becomes Blender's 1e10.
        let z = find(&channels, "Z");
        for (i, (got, want)) in z.data.iter().zip(&depth_z.data).enumerate() {
            let want = if i == 5 { 1.0e10 } else { *want };
            assert_eq!(got.to_bits(), want.to_bits(), "Z sample {i}");
        }
    }

    #[test]
    fn layers_are_written_under_their_names() {
        let (w, h) = (5, 4);
        let rgba = |seed| Planes {
            width: w,
            height: h,
            rgb: Some([
                pattern(w, h, seed),
                pattern(w, h, seed + 0.1),
                pattern(w, h, 0.2),
            ]),
            alpha: Some(pattern(w, h, seed + 0.3)),
            depth_z: None,
            depth_ray: None,
            depth_median: None,
        };
        let (main, env) = (rgba(0.1), rgba(0.5));
        let file = TempFile::new("layers");
        let header = ExrHeader {
            pixel_aspect: 2.0,
            ..ExrHeader::default()
        };
        write_exr_layers(&file.0, &main, &[("env", &env)], &header).unwrap();
        let meta = exr::meta::MetaData::read_from_file(&file.0, false).unwrap();
        assert_eq!(meta.headers[0].shared_attributes.pixel_aspect, 2.0);
        let channels = read_exr_channels(&file.0).unwrap();
        let mut names: Vec<&str> = channels.iter().map(|(n, _)| n.as_str()).collect();
        names.sort_unstable();
        assert_eq!(
            names,
            ["A", "B", "G", "R", "env.A", "env.B", "env.G", "env.R"]
        );
        assert_eq!(
            find(&channels, "env.R").data,
            env.rgb.as_ref().unwrap()[0].data
        );
        assert_eq!(find(&channels, "A").data, main.alpha.as_ref().unwrap().data);
        let small = rgba(0.2);
        let small = Planes { width: 4, ..small };
        let e =
            write_exr_layers(&file.0, &main, &[("x", &small)], &ExrHeader::default()).unwrap_err();
        assert!(e.to_string().contains("layer x"), "{e}");
    }

    #[test]
    fn only_present_planes_are_written() {
        let planes = Planes {
            width: 3,
            height: 2,
            rgb: None,
            alpha: None,
            depth_z: None,
            depth_ray: Some(Plane::filled(3, 2, f32::INFINITY)),
            depth_median: None,
        };
        let file = TempFile::new("ray-only");
        write_exr(&file.0, &planes).unwrap();
        let channels = read_exr_channels(&file.0).unwrap();
        assert_eq!(channels.len(), 1);
        assert_eq!(channels[0].0, "depth.ray");
        assert!(channels[0].1.data.iter().all(|&d| d == 1.0e10));
    }

    #[test]
    fn missing_directory_is_an_io_error_naming_the_path() {
        let dir = TempFile::new("no-such-dir");
        let path = dir.0.join("out.exr");
        let planes = Planes {
            width: 2,
            height: 2,
            rgb: None,
            alpha: Some(Plane::filled(2, 2, 1.0)),
            depth_z: None,
            depth_ray: None,
            depth_median: None,
        };
        match write_exr(&path, &planes) {
            Err(Error::Io { path: p, .. }) => assert_eq!(p, path),
            other => panic!("expected an Io error, got {other:?}"),
        }
    }

    #[test]
    fn refuses_no_planes_and_mismatched_sizes() {
        let mut planes = Planes {
            width: 4,
            height: 2,
            rgb: None,
            alpha: None,
            depth_z: None,
            depth_ray: None,
            depth_median: None,
        };
        let file = TempFile::new("refused");
        assert!(matches!(
            write_exr(&file.0, &planes),
            Err(Error::Invalid { .. })
        ));
        planes.alpha = Some(Plane::filled(2, 4, 1.0));
        assert!(matches!(
            write_exr(&file.0, &planes),
            Err(Error::Invalid { .. })
        ));
    }

    #[test]
    fn a_non_finite_pixel_is_refused_and_the_previous_frame_kept() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("frame.exr");
        let mut planes = Planes {
            width: 3,
            height: 2,
            rgb: None,
            alpha: Some(Plane::filled(3, 2, 0.5)),
            depth_z: Some(Plane::filled(3, 2, f32::INFINITY)),
            depth_ray: None,
            depth_median: None,
        };
        write_exr(&path, &planes).unwrap();
        let before = std::fs::read(&path).unwrap();
        planes.alpha.as_mut().unwrap().data[4] = f32::NAN;
        let e = write_exr(&path, &planes).unwrap_err().to_string();
        assert!(e.contains("channel A") && e.contains("pixel (1, 1)"), "{e}");
        assert_eq!(std::fs::read(&path).unwrap(), before);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}

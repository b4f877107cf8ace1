//! One frame across machines: a frame cut into horizontal stripes, each rendered by its own
//! task into a file of its own, and the stripes joined into the frame.
//!
//! Stripes start and end on rows of whole render tiles, so a stripe's tiles are the whole
//! frame's tiles and its pixels the whole frame's, bit for bit. The join reads every channel
//! of every stripe (passes and layers alike) and writes the frame as a whole-frame render
//! writes it.

use std::path::{Path, PathBuf};

use nerfx_core::error::{Error, Result};
use nerfx_core::image::{read_exr_image, write_exr_channels, Plane, Window};

/// Most stripes one frame may be cut into.
pub const MAX_STRIPES: u32 = 1024;

/// Stripe `index` (from 1) of `count` of a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stripe {
    /// Which stripe, from 1 (the top) to `count`.
    pub index: u32,
    /// How many stripes the frame is cut into.
    pub count: u32,
}

impl Stripe {
    /// Reads `K/N` (stripe K of N, from 1).
    pub fn parse(text: &str) -> Result<Stripe> {
        let bad = |why: &str| Error::invalid(format!("stripe '{text}'"), why.to_string());
        let (k, n) = text
            .split_once('/')
            .ok_or_else(|| bad("expected K/N, e.g. 2/4 for the second of four stripes"))?;
        let number = |s: &str| {
            s.trim()
                .parse::<u32>()
                .map_err(|_| bad("K and N must be whole numbers"))
        };
        Stripe::new(number(k)?, number(n)?).map_err(|e| match e {
            Error::Invalid { message, .. } => bad(&message),
            other => other,
        })
    }

    /// Stripe `index` of `count`, checked.
    pub fn new(index: u32, count: u32) -> Result<Stripe> {
        check_count(count)?;
        if !(1..=count).contains(&index) {
            return Err(Error::invalid(
                format!("stripe {index}/{count}"),
                format!("the stripe must be 1 to {count}"),
            ));
        }
        Ok(Stripe { index, count })
    }

    /// The rows of a `width`×`height` image this stripe covers: the image's rows of `tile`
    /// pixel tiles shared out as evenly as whole tile rows allow, the top stripe first.
    pub fn window(&self, width: u32, height: u32, tile: u32) -> Result<Window> {
        let tile = tile.max(1);
        let rows = height.div_ceil(tile);
        if self.count > rows {
            return Err(Error::invalid(
                format!("--split-frame {}", self.count),
                format!(
                    "the frame is {height} pixels high: {rows} rows of {tile}-pixel tiles, \
                     fewer than the stripes asked for"
                ),
            ));
        }
        let edge = |k: u32| {
            let row = u64::from(k) * u64::from(rows) / u64::from(self.count);
            (row * u64::from(tile)).min(u64::from(height)) as u32
        };
        Ok(Window::new(
            0,
            edge(self.index - 1),
            width,
            edge(self.index),
        ))
    }

    /// Where this stripe of the frame written to `frame` goes: beside it, named for the
    /// stripe (`comp.1001.exr` → `comp.1001.stripe2of4.exr`).
    pub fn path(&self, frame: &Path) -> PathBuf {
        let stem = frame
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        let tag = format!("stripe{}of{}", self.index, self.count);
        let name = match frame.extension() {
            Some(ext) => format!("{stem}.{tag}.{}", ext.to_string_lossy()),
            None => format!("{stem}.{tag}"),
        };
        frame.with_file_name(name)
    }
}

/// Refuses a stripe count outside 1..=[`MAX_STRIPES`].
pub fn check_count(count: u32) -> Result<()> {
    if (1..=MAX_STRIPES).contains(&count) {
        Ok(())
    } else {
        Err(Error::invalid(
            format!("--split-frame {count}"),
            format!("expected 1 to {MAX_STRIPES} stripes"),
        ))
    }
}

/// Joins the `count` stripes of the frame written to `frame` (each from [`Stripe::path`])
/// into `frame`, every channel of every stripe, and removes the stripes once the frame is
/// written. The stripes must agree in width, channels and pixel aspect.
pub fn assemble(frame: &Path, count: u32) -> Result<()> {
    check_count(count)?;
    let mut joined: Vec<(String, Plane)> = Vec::new();
    let mut width = 0;
    let mut height = 0u32;
    let mut header = None;
    let mut stripes = Vec::with_capacity(count as usize);
    for index in 1..=count {
        let path = Stripe { index, count }.path(frame);
        let (mut channels, stripe_header) = read_exr_image(&path)?;
        let pixel_aspect = stripe_header.pixel_aspect;
        channels.sort_by(|a, b| a.0.cmp(&b.0));
        let disagree = |why: String| {
            Error::format(
                &path,
                "",
                format!("stripe {index} of {count} does not fit the stripes above it: {why}"),
            )
        };
        let size = channels.first().map(|(_, p)| (p.width, p.height));
        let Some((w, h)) = size else {
            return Err(Error::format(&path, "", "the stripe holds no channel"));
        };
        if channels.iter().any(|(_, p)| (p.width, p.height) != (w, h)) {
            return Err(Error::format(&path, "", "its channels differ in size"));
        }
        if index == 1 {
            width = w;
            header = Some(stripe_header);
            joined = channels
                .iter()
                .map(|(name, _)| (name.clone(), Plane::filled(w, 0, 0.0)))
                .collect();
        } else if w != width {
            return Err(disagree(format!("{w} pixels wide, not {width}")));
        } else if let Some(aspect) = header.as_ref().map(|h| h.pixel_aspect) {
            if pixel_aspect != aspect {
                return Err(disagree(format!(
                    "pixel aspect {pixel_aspect}, not {aspect}"
                )));
            }
        }
        let names = |c: &[(String, Plane)]| c.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
        if names(&channels) != names(&joined) {
            return Err(disagree(format!(
                "channels {} where the first has {}",
                names(&channels).join(" "),
                names(&joined).join(" ")
            )));
        }
        for ((_, whole), (_, part)) in joined.iter_mut().zip(channels) {
            whole.data.extend_from_slice(&part.data);
            whole.height += part.height;
        }
        height += h;
        stripes.push(path);
    }
    // The frame's header is the first stripe's: every stripe's is the whole frame's.
    write_exr_channels(frame, (width, height), &joined, &header.unwrap_or_default())?;
    for path in stripes {
        std::fs::remove_file(&path).map_err(|e| Error::io(&path, e))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use nerfx_core::image::{
        read_exr_channels, write_exr_layers, ExrHeader, OutputColorSpace, Planes,
    };

    #[test]
    fn stripes_cover_the_frame_on_tile_rows() {
        for (height, count) in [(100, 1), (100, 3), (100, 7), (17, 2), (16, 1)] {
            let mut next = 0;
            for index in 1..=count {
                let w = Stripe::new(index, count)
                    .unwrap()
                    .window(30, height, 16)
                    .unwrap();
                assert_eq!((w.x0, w.x1, w.y0), (0, 30, next), "{height} {count}");
                assert!(w.y1 > w.y0);
                assert!(w.y0.is_multiple_of(16));
                next = w.y1;
            }
            assert_eq!(next, height);
        }
        let e = Stripe::new(3, 3).unwrap().window(30, 20, 16).unwrap_err();
        assert!(e.to_string().contains("fewer than the stripes"), "{e}");
        assert_eq!(Stripe::parse("2/4").unwrap(), Stripe { index: 2, count: 4 });
        for bad in ["", "2", "0/4", "5/4", "a/b", "1/0", "1/5000"] {
            assert!(Stripe::parse(bad).is_err(), "{bad}");
        }
        let p = Stripe::new(2, 4)
            .unwrap()
            .path(Path::new("out/comp.1001.exr"));
        assert_eq!(p, Path::new("out/comp.1001.stripe2of4.exr"));
    }

    fn numbered(w: u32, h: u32, k: f32) -> Plane {
        Plane {
            width: w,
            height: h,
            data: (0..w * h).map(|i| (i as f32 * 0.37 + k).sin()).collect(),
        }
    }

    #[test]
    fn stripes_join_into_the_frame_every_channel_and_layer() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (7, 40);
        let mut depth = numbered(w, h, 3.0);
        depth.data[9] = f32::INFINITY;
        let planes = Planes {
            width: w,
            height: h,
            rgb: Some([
                numbered(w, h, 0.0),
                numbered(w, h, 1.0),
                numbered(w, h, 2.0),
            ]),
            alpha: Some(numbered(w, h, 4.0)),
            depth_z: Some(depth),
            depth_ray: None,
            depth_median: Some(numbered(w, h, 5.0)),
        };
        let layer = Planes {
            depth_z: None,
            depth_median: None,
            ..planes.clone()
        };
        let header = ExrHeader {
            pixel_aspect: 2.0,
            color_space: OutputColorSpace::AcesCg,
            entries: vec![("nerfx/colorspace".into(), "acescg".into())],
            ..ExrHeader::default()
        };
        let whole = dir.path().join("whole.exr");
        write_exr_layers(&whole, &planes, &[("env", &layer)], &header).unwrap();
        let frame = dir.path().join("frame.exr");
        for index in 1..=3 {
            let stripe = Stripe::new(index, 3).unwrap();
            let window = stripe.window(w, h, 16).unwrap();
            let cut = |p: &Planes| p.crop(window).unwrap();
            write_exr_layers(
                &stripe.path(&frame),
                &cut(&planes),
                &[("env", &cut(&layer))],
                &header,
            )
            .unwrap();
        }
        assemble(&frame, 3).unwrap();
        // Byte for byte the whole frame's file, and the stripes are gone.
        assert_eq!(
            std::fs::read(&frame).unwrap(),
            std::fs::read(&whole).unwrap()
        );
        let mut left: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        left.sort();
        assert_eq!(left, ["frame.exr", "whole.exr"]);
        assert_eq!(
            read_exr_channels(&frame).unwrap().len(),
            read_exr_channels(&whole).unwrap().len()
        );
        // A missing stripe names itself.
        let e = assemble(&dir.path().join("other.exr"), 2).unwrap_err();
        assert!(e.to_string().contains("other.stripe1of2.exr"), "{e}");
    }
}

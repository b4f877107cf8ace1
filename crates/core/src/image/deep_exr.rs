//! Deep images and their OpenEXR output: a deep scanline file (the kind Nuke's DeepRead reads)
//! with channels `R G B A Z ZBack`, 32-bit float, written by OpenEXR's own library.
//!
//! A pixel holds any number of samples, each `[Z, ZBack]` in camera Z (Blender units, the flat
//! `Z` pass's depth), with its own premultiplied colour and alpha: a volume sample where
//! `Z < ZBack`, a point sample (a splat fragment) where they are equal. Samples are sorted
//! front to back and do not overlap (OpenEXR's *tidy* state, which the header's
//! `deepImageState` says), so compositing them front to back with *over* gives the flat
//! render's pixel.
//!
//! The writer is a small C++ file over `ImfDeepScanLineOutputFile` (the `exr` crate does not
//! write deep data), built where pkg-config finds OpenEXR; other builds refuse with a message
//! naming the missing library ([`deep_exr_available`]).

use std::path::Path;

use crate::error::{Error, Result};
use crate::image::ExrHeader;

/// One deep sample: `[front, back]` in camera Z and its premultiplied colour and alpha.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DeepSample {
    /// `Z`: where the sample starts.
    pub front: f32,
    /// `ZBack`: where it ends (`front` for a point sample).
    pub(crate) back: f32,
    /// Premultiplied colour.
    pub rgb: [f32; 3],
    /// Opacity of the sample alone.
    pub alpha: f32,
}

/// A deep image: per pixel (row-major from the top-left) its samples, front to back.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DeepImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Where each pixel's samples start in `samples`, and one past the last pixel's end
    /// (`width·height + 1` entries).
    pub(crate) offsets: Vec<u64>,
    /// Every pixel's samples, one pixel after the other.
    pub samples: Vec<DeepSample>,
}

impl DeepImage {
    /// A `width`×`height` image of pixels without samples.
    pub fn empty(width: u32, height: u32) -> Self {
        DeepImage {
            width,
            height,
            offsets: vec![0; width as usize * height as usize + 1],
            samples: Vec::new(),
        }
    }

    /// The samples of pixel `p` (row-major), to change them in place.
    pub(crate) fn pixel_mut(&mut self, p: usize) -> &mut [DeepSample] {
        &mut self.samples[self.offsets[p] as usize..self.offsets[p + 1] as usize]
    }

    /// The largest and the mean count of samples a pixel holds.
    pub fn sample_counts(&self) -> (usize, f64) {
        let counts = self.offsets.windows(2).map(|w| (w[1] - w[0]) as usize);
        let max = counts.clone().max().unwrap_or(0);
        let pixels = (self.width as usize * self.height as usize).max(1);
        (max, self.samples.len() as f64 / pixels as f64)
    }

    /// Whether every pixel's samples are sorted front to back and do not overlap, with
    /// `Z ≤ ZBack` and finite values: OpenEXR's *tidy* state.
    pub fn is_tidy(&self) -> bool {
        self.offsets.windows(2).all(|w| {
            let pixel = &self.samples[w[0] as usize..w[1] as usize];
            pixel.iter().all(|s| {
                s.front.is_finite()
                    && s.back.is_finite()
                    && s.front <= s.back
                    && s.alpha.is_finite()
            }) && pixel.windows(2).all(|p| p[0].back <= p[1].front)
        })
    }
}

/// Whether this build writes deep EXR files (it was built where OpenEXR was found).
pub fn deep_exr_available() -> bool {
    cfg!(nerfx_openexr)
}

/// Writes `image` to `path` as a deep scanline EXR (module docs) with `header`'s entries
/// (the flat file's: chromaticities, pixel aspect, camera, frame rate, text entries), through
/// the project's atomic output writer: a failed write leaves what stood at `path`.
///
/// Errors: [`Error::Invalid`] when this build has no OpenEXR, the image is empty or its
/// offsets disagree with its size, a sample is not finite, or OpenEXR refuses the file
/// (its message); [`Error::Io`] naming `path`.
pub fn write_deep_exr(path: &Path, image: &DeepImage, header: &ExrHeader) -> Result<()> {
    let what = || format!("deep EXR {}", path.display());
    if !deep_exr_available() {
        return Err(Error::invalid(
            what(),
            "this build of nerfx has no OpenEXR library, which writes deep files: install \
             OpenEXR's development files (Debian: apt-get install libopenexr-dev) and build \
             nerfx again",
        ));
    }
    let pixels = image.width as usize * image.height as usize;
    if pixels == 0 {
        return Err(Error::invalid(what(), "an empty image"));
    }
    if image.offsets.len() != pixels + 1
        || image.offsets.first() != Some(&0)
        || image.offsets.last() != Some(&(image.samples.len() as u64))
        || image.offsets.windows(2).any(|w| w[1] < w[0])
    {
        return Err(Error::invalid(
            what(),
            "its sample offsets disagree with its size",
        ));
    }
    if let Some(i) = image.samples.iter().position(|s| {
        !(s.front.is_finite() && s.back.is_finite() && s.alpha.is_finite())
            || s.rgb.iter().any(|c| !c.is_finite())
    }) {
        let p = image.offsets.partition_point(|&o| o <= i as u64) - 1;
        return Err(Error::invalid(
            what(),
            format!(
                "pixel ({}, {}) holds a sample that is not finite: not written",
                p % image.width as usize,
                p / image.width as usize
            ),
        ));
    }
    if !(header.pixel_aspect.is_finite() && header.pixel_aspect > 0.0) {
        return Err(Error::invalid(
            format!("{}: pixel aspect", what()),
            format!("expected a positive number, got {}", header.pixel_aspect),
        ));
    }
    crate::output::replace_file(path, |temp| {
        ffi::write(temp, path, image, header, image.is_tidy())
    })
}

#[cfg(nerfx_openexr)]
mod ffi {
    //! The call into `deep_exr.cpp`.
    use std::ffi::{c_char, c_int, CString};
    use std::os::unix::ffi::OsStrExt;
    use std::path::Path;

    use super::DeepImage;
    use crate::error::{Error, Result};
    use crate::image::ExrHeader;

    /// `NerfxDeepHeader` in `deep_exr.cpp`, field for field.
    #[repr(C)]
    struct NerfxDeepHeader {
        pixel_aspect: f32,
        chromaticities: [f32; 8],
        has_world_to_camera: c_int,
        world_to_camera: [f32; 16],
        has_world_to_ndc: c_int,
        world_to_ndc: [f32; 16],
        has_fps: c_int,
        fps_numerator: c_int,
        fps_denominator: u32,
        tidy: c_int,
        entries: usize,
        keys: *const *const c_char,
        values: *const *const c_char,
    }

    extern "C" {
        fn nerfx_write_deep_scanline(
            path: *const c_char,
            width: c_int,
            height: c_int,
            counts: *const u32,
            offsets: *const u64,
            channels: *const *const f32,
            header: *const NerfxDeepHeader,
            error: *mut c_char,
            error_len: usize,
        ) -> c_int;
    }

    /// A text without NUL bytes, as OpenEXR stores it (a C string).
    fn c_text(text: &[u8], what: &str, path: &Path) -> Result<CString> {
        CString::new(text).map_err(|_| {
            Error::invalid(
                format!("deep EXR {}", path.display()),
                format!("{what} holds a NUL byte, which an EXR cannot store"),
            )
        })
    }

    /// Writes `image` to `temp` (the caller's temporary path for `path`, which errors name).
    pub(super) fn write(
        temp: &Path,
        path: &Path,
        image: &DeepImage,
        header: &ExrHeader,
        tidy: bool,
    ) -> Result<()> {
        let size = |n: u32| {
            c_int::try_from(n).map_err(|_| {
                Error::invalid(
                    format!("deep EXR {}", path.display()),
                    format!("{n} pixels is too wide for OpenEXR"),
                )
            })
        };
        let (width, height) = (size(image.width)?, size(image.height)?);
        let c_path = c_text(temp.as_os_str().as_bytes(), "the path", path)?;
        let counts: Vec<u32> = image
            .offsets
            .windows(2)
            .map(|w| u32::try_from(w[1] - w[0]).unwrap_or(u32::MAX))
            .collect();
        let channel = |f: &dyn Fn(&super::DeepSample) -> f32| -> Vec<f32> {
            image.samples.iter().map(f).collect()
        };
        let channels = [
            channel(&|s| s.rgb[0]),
            channel(&|s| s.rgb[1]),
            channel(&|s| s.rgb[2]),
            channel(&|s| s.alpha),
            channel(&|s| s.front),
            channel(&|s| s.back),
        ];
        // A pixel's pointer is formed even where it holds no sample: give every channel an
        // element to point into.
        let channels: Vec<Vec<f32>> = channels
            .into_iter()
            .map(|mut c| {
                c.push(0.0);
                c
            })
            .collect();
        let pointers: Vec<*const f32> = channels.iter().map(|c| c.as_ptr()).collect();
        let mut keys = Vec::with_capacity(header.entries.len());
        let mut values = Vec::with_capacity(header.entries.len());
        for (key, value) in &header.entries {
            keys.push(c_text(
                key.as_bytes(),
                &format!("header entry {key}"),
                path,
            )?);
            values.push(c_text(
                value.as_bytes(),
                &format!("header entry {key}"),
                path,
            )?);
        }
        let key_ptrs: Vec<*const c_char> = keys.iter().map(|k| k.as_ptr()).collect();
        let value_ptrs: Vec<*const c_char> = values.iter().map(|v| v.as_ptr()).collect();
        let c = header.color_space.chromaticities();
        let mut chromaticities = [0.0f32; 8];
        for (i, xy) in [c.red, c.green, c.blue, c.white].iter().enumerate() {
            chromaticities[2 * i] = xy[0] as f32;
            chromaticities[2 * i + 1] = xy[1] as f32;
        }
        let camera = header.camera.as_ref();
        let (fps_numerator, fps_denominator) = header.frames_per_second.unwrap_or((0, 1));
        let c_header = NerfxDeepHeader {
            pixel_aspect: header.pixel_aspect as f32,
            chromaticities,
            has_world_to_camera: c_int::from(camera.is_some()),
            world_to_camera: camera.map_or([0.0; 16], |c| c.world_to_camera),
            has_world_to_ndc: c_int::from(camera.and_then(|c| c.world_to_ndc).is_some()),
            world_to_ndc: camera.and_then(|c| c.world_to_ndc).unwrap_or([0.0; 16]),
            has_fps: c_int::from(header.frames_per_second.is_some()),
            fps_numerator,
            fps_denominator,
            tidy: c_int::from(tidy),
            entries: key_ptrs.len(),
            keys: key_ptrs.as_ptr(),
            values: value_ptrs.as_ptr(),
        };
        let mut error = vec![0 as c_char; 1024];
        // SAFETY: every pointer is to a live buffer of the length the C side reads: `counts`
        // and `offsets` hold a pixel each (plus one offset), each channel holds
        // `samples.len() + 1` floats, which covers `offsets[p] + counts[p]` for every pixel
        // (checked by the caller), and the header's arrays hold `entries` C strings.
        let status = unsafe {
            nerfx_write_deep_scanline(
                c_path.as_ptr(),
                width,
                height,
                counts.as_ptr(),
                image.offsets.as_ptr(),
                pointers.as_ptr(),
                &c_header,
                error.as_mut_ptr(),
                error.len(),
            )
        };
        if status == 0 {
            Ok(())
        } else {
            let message: Vec<u8> = error
                .iter()
                .take_while(|&&c| c != 0)
                .map(|&c| c as u8)
                .collect();
            Err(Error::invalid(
                format!("deep EXR {}", path.display()),
                format!("OpenEXR: {}", String::from_utf8_lossy(&message)),
            ))
        }
    }
}

#[cfg(not(nerfx_openexr))]
mod ffi {
    //! This build has no OpenEXR: [`write_deep_exr`](super::write_deep_exr) refuses first.
    use std::path::Path;

    use super::DeepImage;
    use crate::error::{Error, Result};
    use crate::image::ExrHeader;

    pub(super) fn write(
        _: &Path,
        path: &Path,
        _: &DeepImage,
        _: &ExrHeader,
        _: bool,
    ) -> Result<()> {
        Err(Error::invalid(
            format!("deep EXR {}", path.display()),
            "this build of nerfx has no OpenEXR library",
        ))
    }
}

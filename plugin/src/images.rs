//! Clip images fetched from the host, released on every path.
//!
//! [`ClipImage::fetch`] wraps `clipGetImage`; the image is released by `clipReleaseImage`
//! when the value drops, so an error anywhere in a render still releases everything it
//! fetched. Only float pixels are accepted (the plugin declares float only), in RGBA or Alpha
//! as declared, or RGB from a host that ignores the declared components.

use openfx_sys::*;

use crate::coords::PixelRect;
use crate::instance::ClipRef;
use crate::pixels::PixelView;
use crate::props::{name, Props};
use crate::status::{check, Failure, Result, FAILED};
use crate::suites::suites;

/// `clipReleaseImage`'s signature.
type ReleaseFn = unsafe extern "C" fn(OfxPropertySetHandle) -> OfxStatus;

/// An image handle that is released on drop, by the `clipReleaseImage` of the image effect
/// suite that fetched it, kept from fetch time: looking the suites up again at release time
/// could fail (or find others) and leak the image.
struct Held {
    handle: OfxPropertySetHandle,
    release: ReleaseFn,
}

impl Drop for Held {
    fn drop(&mut self) {
        // SAFETY: the handle came from clipGetImage of the suite `release` belongs to, and is
        // released once, here.
        unsafe { (self.release)(self.handle) };
    }
}

/// A fetched image and a checked view of its pixels.
pub struct ClipImage {
    _held: Held,
    /// The pixels (bounds, row bytes and channels checked).
    pub view: PixelView,
    /// The image holds a single field of fielded footage (`kOfxImagePropField` lower or
    /// upper), not a full frame.
    pub single_field: bool,
    /// The image's colour is not premultiplied by its alpha
    /// (`kOfxImageEffectPropPreMultiplication` is `kOfxImageUnPreMultiplied`): straight-alpha
    /// footage, which must be premultiplied before the core composites it.
    pub straight: bool,
}

/// Floats per pixel for a components string, if the plugin reads it.
fn channels(components: &str) -> Option<usize> {
    let is = |c: &'static [u8]| name(c).to_bytes() == components.as_bytes();
    if is(kOfxImageComponentRGBA) {
        Some(4)
    } else if is(kOfxImageComponentRGB) {
        Some(3)
    } else if is(kOfxImageComponentAlpha) {
        Some(1)
    } else {
        None
    }
}

impl ClipImage {
    /// The image of `clip` at `time` over `region` (canonical coordinates; `None`: the host's
    /// default region). `Ok(None)` when the host has no image there (`kOfxStatFailed`: the
    /// spec says to treat it as transparent black).
    pub fn fetch(
        clip: &ClipRef,
        clip_name: &str,
        time: f64,
        region: Option<[f64; 4]>,
    ) -> Result<Option<Self>> {
        let s = suites()?;
        let get = s
            .effect
            .clipGetImage
            .ok_or_else(|| Failure::missing_suite("image effect suite's clipGetImage"))?;
        // Taken now, before an image exists that it must release.
        let release = s
            .effect
            .clipReleaseImage
            .ok_or_else(|| Failure::missing_suite("image effect suite's clipReleaseImage"))?;
        let rect = region.map(|r| OfxRectD {
            x1: r[0],
            y1: r[1],
            x2: r[2],
            y2: r[3],
        });
        let rect_ptr = rect
            .as_ref()
            .map_or(std::ptr::null(), |r| r as *const OfxRectD);
        let mut handle: OfxPropertySetHandle = std::ptr::null_mut();
        // SAFETY: a live clip handle, a rectangle or null, an out pointer.
        let status = unsafe { get(clip.handle, time, rect_ptr, &mut handle) };
        if status == FAILED {
            return Ok(None);
        }
        check(format_args!("clipGetImage({clip_name}, {time})"), status)?;
        if handle.is_null() {
            return Ok(None);
        }
        let held = Held { handle, release };
        // SAFETY: the image's property set is valid until released (by `held`).
        let props = unsafe { Props::new(handle, s.property) };
        let err = |what: String| Failure::failed(format!("clip {clip_name}: {what}"));
        let depth = props.string(name(kOfxImageEffectPropPixelDepth))?;
        if depth.as_bytes() != name(kOfxBitDepthFloat).to_bytes() {
            return Err(err(format!("pixel depth {depth}, expected 32-bit float")));
        }
        let components = props.string(name(kOfxImageEffectPropComponents))?;
        let n = channels(&components)
            .ok_or_else(|| err(format!("components {components}, expected RGBA or Alpha")))?;
        let bounds = PixelRect::from_ints(props.ints::<4>(name(kOfxImagePropBounds))?);
        let row_bytes = props.int(name(kOfxImagePropRowBytes))?;
        let data = props.pointer(name(kOfxImagePropData))?;
        if data.is_null() {
            // An image with no pixels: some hosts present an absent input this way.
            return Ok(None);
        }
        // SAFETY: the host lays the image out as its bounds and row bytes say, for as long
        // as it is held, which `ClipImage` ensures by holding `held` with the view.
        let view = unsafe { PixelView::new(data, bounds, row_bytes, n) }.map_err(err)?;
        let field = props.string(name(kOfxImagePropField)).unwrap_or_default();
        let single_field = [kOfxImageFieldLower.as_slice(), kOfxImageFieldUpper]
            .into_iter()
            .any(|f| name(f).to_bytes() == field.as_bytes());
        // Premultiplied when the host does not say (the spec's default for RGBA).
        let straight = props
            .string(name(kOfxImageEffectPropPreMultiplication))
            .is_ok_and(|p| p.as_bytes() == name(kOfxImageUnPreMultiplied).to_bytes());
        Ok(Some(ClipImage {
            _held: held,
            view,
            single_field,
            straight,
        }))
    }
}

/// Whether `clip` is connected.
pub fn connected(clip: &ClipRef) -> Result<bool> {
    let s = suites()?;
    // SAFETY: the clip's property set lives as long as the instance.
    let p = unsafe { Props::new(clip.props, s.property) };
    Ok(p.int(name(kOfxImageClipPropConnected))? != 0)
}

/// The pixel aspect ratio of `clip` (1 when the host does not say or says nonsense).
pub fn pixel_aspect(clip: &ClipRef) -> f64 {
    let Ok(s) = suites() else { return 1.0 };
    // SAFETY: as in `connected`.
    let p = unsafe { Props::new(clip.props, s.property) };
    match p.double(name(kOfxImagePropPixelAspectRatio)) {
        Ok(par) if par.is_finite() && par > 0.0 => par,
        _ => 1.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_rgba_rgb_and_alpha_only() {
        assert_eq!(channels("OfxImageComponentRGBA"), Some(4));
        assert_eq!(channels("OfxImageComponentAlpha"), Some(1));
        assert_eq!(channels("OfxImageComponentRGB"), Some(3));
        assert_eq!(channels("OfxImageComponentRGBAZ"), None);
        assert_eq!(channels(""), None);
    }

    #[test]
    fn a_held_image_is_released_by_the_function_kept_at_fetch() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        static RELEASED: AtomicUsize = AtomicUsize::new(0);
        unsafe extern "C" fn release(h: OfxPropertySetHandle) -> OfxStatus {
            assert_eq!(h as usize, 0x40);
            RELEASED.fetch_add(1, Ordering::SeqCst);
            0
        }
        // No host is loaded in this test: the suites cannot be looked up at drop time.
        assert!(suites().is_err());
        drop(Held {
            handle: 0x40 as OfxPropertySetHandle,
            release,
        });
        assert_eq!(RELEASED.load(Ordering::SeqCst), 1);
    }
}

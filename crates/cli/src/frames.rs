//! The frames a command renders and the files they go to: frame lists (`1001-1100x5`) and
//! output name patterns (`out/comp.####.exr`).

use std::path::{Path, PathBuf};

use nerfx_core::error::{Error, Result};

/// Most frames one `--frames` may name (a farm splits longer ranges over commands).
pub const MAX_FRAMES: usize = 1_000_000;

/// Parses a frame list: `1001`, `1001-1010`, `1001-1100x5` (every 5th; `1001-1100:5`, as Open
/// Job Description writes a step, is the same), or several of those separated by commas
/// (`1,5,10-12`). Frames come out in the order given, without repeats.
///
/// ```
/// assert_eq!(nerfx::frames::parse_frames("7,1-3,2").unwrap(), vec![7, 1, 2, 3]);
/// assert_eq!(nerfx::frames::parse_frames("10-20x5").unwrap(), vec![10, 15, 20]);
/// assert_eq!(nerfx::frames::parse_frames("10-20:5").unwrap(), vec![10, 15, 20]);
/// ```
pub fn parse_frames(spec: &str) -> Result<Vec<i64>> {
    let bad = |why: &str| Error::invalid(format!("frames '{spec}'"), why.to_string());
    let mut frames = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for part in spec.split(',').map(str::trim) {
        let (range, step) = match part.split_once(['x', ':']) {
            Some((r, s)) => (
                r,
                s.parse::<i64>()
                    .map_err(|_| bad("the step after 'x' or ':' is not a whole number"))?,
            ),
            None => (part, 1),
        };
        if step < 1 {
            return Err(bad("the step must be ≥ 1"));
        }
        // A '-' after the first character separates the range (the first may be a sign).
        let (first, last) = match range.get(1..).and_then(|r| r.find('-')) {
            Some(i) => (&range[..=i], &range[i + 2..]),
            None => (range, range),
        };
        let parse = |s: &str| {
            s.trim()
                .parse::<i64>()
                .map_err(|_| bad("expected frame numbers like 1001-1010"))
        };
        let (first, last) = (parse(first)?, parse(last)?);
        if last < first {
            return Err(bad("a range must not run backwards"));
        }
        // In i128: no range of i64 frames overflows it.
        let count = (i128::from(last) - i128::from(first)) / i128::from(step) + 1;
        if count > (MAX_FRAMES - frames.len()) as i128 {
            return Err(bad(&format!(
                "more than {MAX_FRAMES} frames in one command; split the range"
            )));
        }
        for k in 0..count {
            // first + k·step ≤ last, so it fits in i64.
            let f = (i128::from(first) + k * i128::from(step)) as i64;
            if seen.insert(f) {
                frames.push(f);
            }
        }
    }
    Ok(frames)
}

/// The output path for `frame`: the last run of `#` in `pattern` becomes the frame number,
/// zero-padded to the run's length (`out/comp.####.exr` → `out/comp.1001.exr`). A pattern
/// without `#` gets `.<frame>` before its extension when several frames are rendered.
///
/// ```
/// use std::path::Path;
/// let p = nerfx::frames::frame_path(Path::new("out/comp.####.exr"), 7, true);
/// assert_eq!(p, Path::new("out/comp.0007.exr"));
/// ```
pub fn frame_path(pattern: &Path, frame: i64, several: bool) -> PathBuf {
    let text = pattern.to_string_lossy();
    if let Some(end) = text.rfind('#') {
        let start = text[..=end].trim_end_matches('#').len();
        let width = end + 1 - start;
        let number = if frame < 0 {
            format!("-{:0width$}", -frame, width = width.saturating_sub(1))
        } else {
            format!("{frame:0width$}")
        };
        return PathBuf::from(format!("{}{}{}", &text[..start], number, &text[end + 1..]));
    }
    if !several {
        return pattern.to_path_buf();
    }
    let stem = pattern
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let name = match pattern.extension() {
        Some(ext) => format!("{stem}.{frame}.{}", ext.to_string_lossy()),
        None => format!("{stem}.{frame}"),
    };
    pattern.with_file_name(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_lists_at_the_ends_of_i64_end_or_are_refused() {
        let max = i64::MAX;
        assert_eq!(parse_frames(&max.to_string()).unwrap(), vec![max]);
        assert_eq!(
            parse_frames(&format!("{}-{max}", max - 2)).unwrap(),
            vec![max - 2, max - 1, max]
        );
        assert_eq!(
            parse_frames(&format!("{}", i64::MIN)).unwrap(),
            vec![i64::MIN]
        );
        // A step past the end of the range adds nothing.
        assert_eq!(
            parse_frames(&format!("1001-1003x{max}")).unwrap(),
            vec![1001]
        );
        let e = parse_frames(&format!("{}-{max}", i64::MIN))
            .unwrap_err()
            .to_string();
        assert!(e.contains("more than 1000000 frames"), "{e}");
        // The limit counts every part together, and repeats are dropped in linear time.
        assert_eq!(parse_frames("1-600000,1-300000").unwrap().len(), 600_000);
        assert!(parse_frames("1-600000,700000-1300000").is_err());
    }

    #[test]
    fn frame_lists() {
        assert_eq!(parse_frames("1001").unwrap(), vec![1001]);
        assert_eq!(
            parse_frames("1001-1004").unwrap(),
            vec![1001, 1002, 1003, 1004]
        );
        assert_eq!(parse_frames("-2-1").unwrap(), vec![-2, -1, 0, 1]);
        assert_eq!(parse_frames("1-10x4, 3").unwrap(), vec![1, 5, 9, 3]);
        assert_eq!(parse_frames("1-10:4").unwrap(), vec![1, 5, 9]);
        for bad in [
            "",
            "a-b",
            "5-1",
            "1-10x0",
            "1-10:x2",
            "1-2-3",
            "1-1000000000",
        ] {
            let e = parse_frames(bad).unwrap_err().to_string();
            assert!(e.contains(&format!("'{bad}'")), "{e}");
        }
    }

    #[test]
    fn frame_paths() {
        let p = |s: &str, f, several| frame_path(Path::new(s), f, several);
        assert_eq!(p("a/b.####.exr", 1001, true), Path::new("a/b.1001.exr"));
        assert_eq!(p("a/b.##.exr", 1001, true), Path::new("a/b.1001.exr"));
        assert_eq!(p("b_#.exr", -3, true), Path::new("b_-3.exr"));
        assert_eq!(p("b.exr", 12, true), Path::new("b.12.exr"));
        assert_eq!(p("b.exr", 12, false), Path::new("b.exr"));
    }
}

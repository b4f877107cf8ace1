//! The crate's one error type, classified by cause.

use std::fmt;
use std::path::PathBuf;

/// A number for a message: as Rust writes it when ordinary, in exponent form (`1e308`,
/// `3.4028235e38`, `1e-9`) when so large or small that plain digits would run to hundreds.
pub fn number<T: Copy + Into<f64> + fmt::Display + fmt::LowerExp>(x: T) -> String {
    let v: f64 = x.into();
    if v != 0.0 && v.is_finite() && !(1e-5..1e16).contains(&v.abs()) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// Everything that can go wrong in the core, by cause. Each variant carries enough context
/// (file, field, frame) for an artist to find and fix the input.
#[derive(Debug)]
pub enum Error {
    /// Reading or writing a file failed.
    Io {
        /// The file involved.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A file was read but its contents do not follow the expected format or schema.
    Format {
        /// The file involved (empty when the data did not come from a file).
        path: PathBuf,
        /// Where in the file: a JSON path such as `frames[3].camera.lens`, or a byte offset.
        location: String,
        /// What is wrong.
        message: String,
    },
    /// A value is out of its valid range (NaN matrix, zero lens, absurd resolution, ...).
    Invalid {
        /// What the value is, e.g. `camera.matrix_world` or `frame 1004: nerf object matrix`.
        what: String,
        /// Why it was refused.
        message: String,
    },
    /// A feature that is recognised but not supported.
    Unsupported(String),
}

/// Results of the core.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An [`Error::Invalid`] for `what`.
    pub fn invalid(what: impl Into<String>, message: impl Into<String>) -> Self {
        Error::Invalid {
            what: what.into(),
            message: message.into(),
        }
    }

    /// An [`Error::Format`] for a location in a file.
    pub fn format(
        path: impl Into<PathBuf>,
        location: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Error::Format {
            path: path.into(),
            location: location.into(),
            message: message.into(),
        }
    }

    /// An [`Error::Io`] for a file.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Error::Io { path, source } => write!(f, "{}: {source}", path.display()),
            Error::Format {
                path,
                location,
                message,
            } => {
                if location.is_empty() {
                    write!(f, "{}: {message}", path.display())
                } else {
                    write!(f, "{}: {location}: {message}", path.display())
                }
            }
            Error::Invalid { what, message } => write!(f, "{what}: {message}"),
            Error::Unsupported(what) => write!(f, "not supported: {what}"),
        }
    }
}

impl std::error::Error for Error {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Error::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

#[cfg(test)]
mod number_tests {
    use super::number;

    #[test]
    fn numbers_in_messages_stay_short() {
        assert_eq!(number(1e308), "1e308");
        assert_eq!(number(-1e300), "-1e300");
        assert_eq!(number(f32::MAX), "3.4028235e38");
        assert_eq!(number(1e-9), "1e-9");
        assert_eq!(number(0.25), "0.25");
        assert_eq!(number(1920.0), "1920");
        assert_eq!(number(0.0), "0");
        assert_eq!(number(f64::NAN), "NaN");
        assert_eq!(number(f64::INFINITY), "inf");
    }
}

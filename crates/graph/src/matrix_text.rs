//! How a matrix parameter travels as text: OpenFX has no 4×4 parameter, so the plugin
//! publishes [`crate::ParamKind::Matrix`] as a single-line string parameter, and the
//! graph renderer sets it through the host the same way.

/// How a matrix default is shown: rows separated by commas, e.g.
/// `1 0 0 0, 0 1 0 0, 0 0 1 0, 0 0 0 1`.
pub fn matrix_text(m: &[f64; 16]) -> String {
    m.chunks(4)
        .map(|row| {
            row.iter()
                .map(|v| v.to_string())
                .collect::<Vec<_>>()
                .join(" ")
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The 16 finite numbers of a matrix string, row-major. Separators are white space, commas,
/// semicolons and brackets, so a pasted Python or NumPy list also reads.
pub fn parse_matrix(text: &str) -> Result<[f64; 16], String> {
    let tokens: Vec<&str> = text
        .split(|c: char| c.is_whitespace() || ",;[]()".contains(c))
        .filter(|t| !t.is_empty())
        .collect();
    if tokens.len() != 16 {
        return Err(format!(
            "expected 16 numbers (a 4×4 matrix, row-major), got {} in {text:?}",
            tokens.len()
        ));
    }
    let mut m = [0.0; 16];
    for (i, (slot, t)) in m.iter_mut().zip(&tokens).enumerate() {
        let v: f64 = t
            .parse()
            .map_err(|_| format!("entry {i} ({t:?}) is not a number"))?;
        if !v.is_finite() {
            return Err(format!("entry {i} ({t:?}) is not finite"));
        }
        *slot = v;
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matrices_read_row_major_with_any_separator() {
        let m = parse_matrix("1 2 3 4, 5 6 7 8; [9 10 11 12] (13,14,15,-1.5e2)").unwrap();
        let want: Vec<f64> = (1..=15).map(f64::from).chain([-150.0]).collect();
        assert_eq!(m.to_vec(), want);
    }

    #[test]
    fn matrix_text_reads_back() {
        let m = [
            0.5, -2.0, 0.0, 1e-7, 0.1, 1.0, 3.25, 10.0, 0.0, 0.0, 1.0, -4.5, 0.0, 0.0, 0.0, 1.0,
        ];
        assert_eq!(
            matrix_text(&[
                1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0
            ]),
            "1 0 0 0, 0 1 0 0, 0 0 1 0, 0 0 0 1"
        );
        assert_eq!(parse_matrix(&matrix_text(&m)).unwrap(), m);
    }

    #[test]
    fn bad_matrices_say_why() {
        let e = parse_matrix("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0").unwrap_err();
        assert!(
            e.contains("expected 16 numbers") && e.contains("got 15"),
            "{e}"
        );
        let e = parse_matrix("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 x").unwrap_err();
        assert!(e.contains("entry 15") && e.contains("not a number"), "{e}");
        let e = parse_matrix("1 0 0 0 0 NaN 0 0 0 0 1 0 0 0 0 1").unwrap_err();
        assert!(e.contains("entry 5") && e.contains("not finite"), "{e}");
        assert!(parse_matrix("").is_err());
    }
}

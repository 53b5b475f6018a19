//! Rows of numbers in text files (PMD, CSV exports): one line of `sep`-separated decimal
//! numbers parsed into `f32` readings, or nothing when the line is not exactly that.
//!
//! The readers keep their own parser for the refusal message (which token, which line); this
//! is their fast path for the lines that are well formed, which is nearly all of them.

/// Parse `line` (without its line end) as exactly `expected` numbers separated by `sep`,
/// each token trimmed of ASCII white space, into `out` (cleared first). Each number is read
/// as `f64` and then rounded to `f32`, as numpy reads a text number into `float32`, so the
/// readings are bit for bit those of the readers' slow path (an overflow gives ±infinity,
/// `nan`/`inf` are read as such). `false` (and `out` unspecified) when a token is empty or not
/// a decimal number, or the count differs.
pub fn parse_row(line: &str, sep: char, expected: usize, out: &mut Vec<f32>) -> bool {
    out.clear();
    out.reserve(expected);
    for token in line.trim_matches(is_blank).split(sep) {
        if out.len() == expected {
            return false;
        }
        match token.trim_matches(is_blank).parse::<f64>() {
            Ok(v) => out.push(v as f32),
            Err(_) => return false,
        }
    }
    out.len() == expected
}

fn is_blank(c: char) -> bool {
    c.is_ascii_whitespace()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(line: &str, n: usize) -> Option<Vec<f32>> {
        let mut out = Vec::new();
        parse_row(line, '\t', n, &mut out).then_some(out)
    }

    #[test]
    fn reads_counts_and_decimals() {
        assert_eq!(
            row("0\t12\t3.5\t-2e1\n", 4),
            Some(vec![0.0, 12.0, 3.5, -20.0])
        );
        assert_eq!(row(" 1 \t 2\t3 ", 3), Some(vec![1.0, 2.0, 3.0]));
    }

    #[test]
    fn rounds_through_f64_like_numpy() {
        let got = row("0.1\t1e308\t-1e400\t1e-50", 4).unwrap();
        assert_eq!(got[0], 0.1f64 as f32);
        assert_eq!(got[1], f32::INFINITY);
        assert_eq!(got[2], f32::NEG_INFINITY);
        assert_eq!(got[3], 0.0);
        assert!(row("nan\t1", 2).unwrap()[0].is_nan());
    }

    #[test]
    fn refuses_what_is_not_exactly_the_row() {
        for bad in [
            "1\t\t3",
            "1\tabc\t3",
            "1\t0x10\t3",
            "1\t2",
            "1\t2\t3\t4",
            "1 2\t3\t4",
            "",
        ] {
            assert_eq!(row(bad, 3), None, "{bad:?}");
        }
    }
}

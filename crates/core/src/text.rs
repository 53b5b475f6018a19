//! Rows of numbers in text files (PMD, CSV exports): one line of `sep`-separated decimal
//! numbers parsed into `f32` readings, or nothing when the line is not exactly that.
//!
//! The readers keep their own parser for the refusal message (which token, which line); this
//! is their fast path for the lines that are well formed, which is nearly all of them.
//!
//! The inside of a JSON list of numbers (an MQTT frame's `values`) is read the same way:
//! [`parse_json_numbers`] reads exactly JSON's number grammar into `f64`, or nothing, and the
//! station's full JSON parse then says what is wrong.

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

/// Parse `text`, the inside of a JSON list (between `[` and `]`), as exactly `expected`
/// elements, each a JSON number (RFC 8259: `-?(0|[1-9][0-9]*)(.[0-9]+)?([eE][+-]?[0-9]+)?`)
/// or `null` (read as NaN), separated by commas with JSON white space (space, tab, CR, LF)
/// around them, into `out` (cleared first). A number is the nearest `f64` (as Python's
/// `float` of the text, and as an integer converted to a float: `-0` is 0). `false` (and
/// `out` unspecified) for anything else: another token, a number beyond the `f64` range, a
/// count other than `expected`.
pub fn parse_json_numbers(text: &[u8], expected: usize, out: &mut Vec<f64>) -> bool {
    out.clear();
    out.reserve(expected);
    let mut k = skip_space(text, 0);
    if k == text.len() {
        return expected == 0;
    }
    loop {
        if out.len() == expected {
            return false;
        }
        let Some((v, end)) = json_element(text, k) else {
            return false;
        };
        out.push(v);
        k = skip_space(text, end);
        match text.get(k) {
            None => return out.len() == expected,
            Some(b',') => k = skip_space(text, k + 1),
            Some(_) => return false,
        }
    }
}

fn skip_space(text: &[u8], mut k: usize) -> usize {
    while k < text.len() && matches!(text[k], b' ' | b'\t' | b'\r' | b'\n') {
        k += 1;
    }
    k
}

fn digits(text: &[u8], mut k: usize) -> usize {
    while k < text.len() && text[k].is_ascii_digit() {
        k += 1;
    }
    k
}

/// One element at `k`: its value and where it ends, or None when it is not a finite number
/// or `null`.
fn json_element(text: &[u8], k: usize) -> Option<(f64, usize)> {
    if text[k..].starts_with(b"null") {
        return Some((f64::NAN, k + 4));
    }
    let start = k;
    let mut k = k;
    if text.get(k) == Some(&b'-') {
        k += 1;
    }
    match text.get(k) {
        Some(b'0') => k += 1,
        Some(b'1'..=b'9') => k = digits(text, k + 1),
        _ => return None,
    }
    let integer = k;
    if text.get(k) == Some(&b'.') {
        let end = digits(text, k + 1);
        if end == k + 1 {
            return None;
        }
        k = end;
    }
    if matches!(text.get(k), Some(b'e' | b'E')) {
        k += 1;
        if matches!(text.get(k), Some(b'+' | b'-')) {
            k += 1;
        }
        let end = digits(text, k);
        if end == k {
            return None;
        }
        k = end;
    }
    // ASCII by construction; Rust's parse gives the nearest f64 (ties to even), as Python does
    let token = std::str::from_utf8(&text[start..k]).ok()?;
    let mut v: f64 = token.parse().ok()?;
    if k == integer && v == 0.0 {
        v = 0.0; // an integer: -0 is the integer 0
    }
    v.is_finite().then_some((v, k))
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

    fn numbers(text: &str, n: usize) -> Option<Vec<f64>> {
        let mut out = Vec::new();
        parse_json_numbers(text.as_bytes(), n, &mut out).then_some(out)
    }

    #[test]
    fn reads_json_numbers_and_nulls() {
        let got = numbers(" 0, -12 ,3.5e-1,\n2E+2,null ,0.1, -0, -0.0", 8).unwrap();
        assert_eq!(&got[..4], &[0.0, -12.0, 0.35, 200.0]);
        assert!(got[4].is_nan());
        assert_eq!(got[5], 0.1);
        assert!(got[6] == 0.0 && got[6].is_sign_positive());
        assert!(got[7] == 0.0 && got[7].is_sign_negative());
        assert_eq!(numbers("", 0), Some(vec![]));
        assert_eq!(numbers(" \n", 0), Some(vec![]));
        assert_eq!(
            numbers("123456789012345678901234567890", 1),
            Some(vec![1.2345678901234568e29])
        );
    }

    #[test]
    fn refuses_what_json_does_not_allow_or_is_not_finite() {
        for bad in [
            "1,,3",
            "1,2,",
            ",1,2",
            "01,2,3",
            "1.,2,3",
            ".5,2,3",
            "+1,2,3",
            "1e,2,3",
            "1,2,3,4",
            "1,2",
            "NaN,1,2",
            "Infinity,1,2",
            "1e400,1,2",
            "-1e400,1,2",
            "true,1,2",
            "1 2,3,4",
            "nul,1,2",
            "\"1\",2,3",
            "1,2,3 x",
            "0x1,2,3",
            "1\u{a0},2,3",
            "-,1,2",
            "1e+,2,3",
        ] {
            assert_eq!(numbers(bad, 3), None, "{bad:?}");
        }
        assert_eq!(numbers("1,2,3", 3), Some(vec![1.0, 2.0, 3.0]));
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

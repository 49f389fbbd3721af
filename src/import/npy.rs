//! NumPy `.npy` arrays of little-endian 64-bit floats, one or two
//! dimensions, in C or Fortran order: what comma2k19's processed logs hold
//! (every signal a folder of two such files, `t` and `value`, without
//! extension).
//!
//! Why not a crate (`npyz`, `ndarray-npy`): they read every dtype through
//! generic element types and report a bad file as their own error kinds;
//! this reads the one dtype the logs use, into the row-major `Vec<f64>` the
//! readers want, and says in the words of [`LoadError`] which file is bad and
//! how (a truncated array, a dtype or shape it is not, a broken header),
//! in fewer lines than the glue a crate would need.
//!
//! The layout (NumPy's `format.py`): the magic `\x93NUMPY`, a major and
//! minor version byte, the header's length (2 bytes little-endian in
//! version 1, 4 in versions 2 and 3), the header (a Python dict literal such
//! as `{'descr': '<f8', 'fortran_order': False, 'shape': (6256, 3), }`),
//! then the data.

use std::path::Path;

use super::LoadError;

const MAGIC: &[u8] = b"\x93NUMPY";

/// A two-dimensional array of `rows x cols` values in row-major order (a
/// one-dimensional array is one column).
#[derive(Clone, Debug, PartialEq)]
pub struct Array {
    pub rows: usize,
    pub cols: usize,
    data: Vec<f64>,
}

impl Array {
    /// Row `r`.
    pub fn row(&self, r: usize) -> &[f64] {
        &self.data[r * self.cols..(r + 1) * self.cols]
    }

    /// Column `c`, copied.
    pub fn column(&self, c: usize) -> Vec<f64> {
        (0..self.rows)
            .map(|r| self.data[r * self.cols + c])
            .collect()
    }
}

/// Read the array in `path`.
pub fn read(path: &Path) -> Result<Array, LoadError> {
    let (bytes, file) = super::read_bytes(path)?;
    parse(&bytes, &file)
}

/// Parse the bytes of an `.npy` file named `file` (for messages).
pub fn parse(bytes: &[u8], file: &str) -> Result<Array, LoadError> {
    let bad = |message: String| LoadError::File {
        file: file.to_string(),
        message,
    };
    if !bytes.starts_with(MAGIC) || bytes.len() < MAGIC.len() + 4 {
        return Err(bad("not a NumPy array (.npy): no \\x93NUMPY magic".into()));
    }
    let major = bytes[MAGIC.len()];
    let (length, start) = match major {
        1 => (
            u16::from_le_bytes([bytes[8], bytes[9]]) as usize,
            MAGIC.len() + 4,
        ),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            MAGIC.len() + 6,
        ),
        v => return Err(bad(format!("NumPy format version {v} is not supported"))),
    };
    let header = bytes
        .get(start..start + length)
        .ok_or_else(|| bad("the header is cut off".into()))?;
    let header = std::str::from_utf8(header)
        .map_err(|_| bad("the header is not text".into()))?
        .replace('"', "'");
    let descr = value_after(&header, "'descr':")
        .and_then(|v| v.strip_prefix('\''))
        .and_then(|v| v.split('\'').next())
        .ok_or_else(|| bad(format!("the header has no dtype ('descr'): {header}")))?;
    if descr != "<f8" {
        return Err(bad(format!(
            "dtype '{descr}' is not supported: the reader takes little-endian float64 ('<f8')"
        )));
    }
    let fortran = match value_after(&header, "'fortran_order':") {
        Some(v) if v.starts_with("True") => true,
        Some(v) if v.starts_with("False") => false,
        _ => return Err(bad(format!("the header has no 'fortran_order': {header}"))),
    };
    let shape_text = value_after(&header, "'shape':")
        .and_then(|v| v.strip_prefix('('))
        .and_then(|v| v.split(')').next())
        .ok_or_else(|| bad(format!("the header has no 'shape': {header}")))?;
    let shape: Vec<usize> = shape_text
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.trim_end_matches('L')
                .parse()
                .map_err(|_| bad(format!("shape ({shape_text}) is not a list of sizes")))
        })
        .collect::<Result<_, _>>()?;
    let (rows, cols) = match shape[..] {
        [n] => (n, 1),
        [n, m] => (n, m),
        _ => {
            return Err(bad(format!(
                "shape ({shape_text}) is not one or two dimensions"
            )));
        }
    };
    let count = rows
        .checked_mul(cols)
        .filter(|c| c.checked_mul(8).is_some())
        .ok_or_else(|| bad(format!("shape ({shape_text}) is too large")))?;
    let data = &bytes[start + length..];
    if data.len() < count * 8 {
        return Err(bad(format!(
            "truncated: shape ({shape_text}) needs {} bytes of data, the file has {}",
            count * 8,
            data.len()
        )));
    }
    let values: Vec<f64> = data[..count * 8]
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]))
        .collect();
    let data = if fortran && cols > 1 {
        // Column-major in the file: element (r, c) at c * rows + r.
        (0..count)
            .map(|i| values[(i % cols) * rows + i / cols])
            .collect()
    } else {
        values
    };
    Ok(Array { rows, cols, data })
}

/// The text after `key` in a header, leading spaces trimmed.
fn value_after<'h>(header: &'h str, key: &str) -> Option<&'h str> {
    header
        .find(key)
        .map(|i| header[i + key.len()..].trim_start())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An `.npy` file of `values` with the header `dict`.
    fn npy(dict: &str, values: &[f64]) -> Vec<u8> {
        let mut header = dict.to_string();
        while !(MAGIC.len() + 4 + header.len() + 1).is_multiple_of(64) {
            header.push(' ');
        }
        header.push('\n');
        let mut out = MAGIC.to_vec();
        out.extend([1, 0]);
        out.extend((header.len() as u16).to_le_bytes());
        out.extend(header.as_bytes());
        for v in values {
            out.extend(v.to_le_bytes());
        }
        out
    }

    #[test]
    fn reads_c_and_fortran_order() {
        let c = npy(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (2, 3), }",
            &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
        );
        let a = parse(&c, "c").unwrap();
        assert_eq!((a.rows, a.cols), (2, 3));
        assert_eq!(a.row(1), &[4.0, 5.0, 6.0]);
        // The same matrix stored column by column.
        let f = npy(
            "{'descr': '<f8', 'fortran_order': True, 'shape': (2, 3), }",
            &[1.0, 4.0, 2.0, 5.0, 3.0, 6.0],
        );
        assert_eq!(parse(&f, "f").unwrap(), a);
        let v = npy(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (3,), }",
            &[7.0, 8.0, 9.0],
        );
        let v = parse(&v, "v").unwrap();
        assert_eq!((v.rows, v.cols), (3, 1));
        assert_eq!(v.column(0), vec![7.0, 8.0, 9.0]);
    }

    #[test]
    fn bad_files_say_what_is_wrong() {
        let err = |b: &[u8]| parse(b, "sig/t").unwrap_err().to_string();
        let good = npy(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (4,), }",
            &[1.0, 2.0, 3.0, 4.0],
        );
        assert!(err(&good[..good.len() - 3]).contains("sig/t: truncated"));
        assert!(err(b"t,value\n1,2\n").contains("no \\x93NUMPY magic"));
        assert!(err(&good[..20]).contains("header is cut off"));
        let ints = npy(
            "{'descr': '<i4', 'fortran_order': False, 'shape': (2,), }",
            &[0.0],
        );
        assert!(err(&ints).contains("dtype '<i4' is not supported"));
        let cube = npy(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (1, 1, 1), }",
            &[0.0],
        );
        assert!(err(&cube).contains("not one or two dimensions"));
        let huge = npy(
            "{'descr': '<f8', 'fortran_order': False, 'shape': (18446744073709551615, 2), }",
            &[],
        );
        assert!(err(&huge).contains("too large"));
        // Every prefix of a good file is an error, never a panic.
        for n in 0..good.len() {
            assert!(parse(&good[..n], "cut").is_err());
        }
    }
}

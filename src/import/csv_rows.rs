//! The rows of a CSV file, read one ahead so that the last is known as the
//! last: a logger that stops in the middle of writing a row (a flat
//! battery, a card pulled) leaves a file whose last line has no line end,
//! and whose last row is short or holds a number cut off. Refusing the
//! whole log for that one unfinished row lost the ride; it is left out,
//! and said. A bad row anywhere else, or a bad last row whose line is
//! complete, is bad input as ever.

use std::io::Read;

use super::LoadError;

/// A reader that remembers the last byte it passed on.
pub(crate) struct LastByte<R> {
    inner: R,
    last: Option<u8>,
}

impl<R> LastByte<R> {
    pub(crate) fn new(inner: R) -> Self {
        Self { inner, last: None }
    }

    /// Whether what has been read so far ends in the middle of a line.
    fn cut_short(&self) -> bool {
        !matches!(self.last, None | Some(b'\n' | b'\r'))
    }
}

impl<R: Read> Read for LastByte<R> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.inner.read(buf)?;
        if n > 0 {
            self.last = Some(buf[n - 1]);
        }
        Ok(n)
    }
}

/// Every record of `reader` passed to `row`, in order: `read` takes the
/// next record (`false` at the end; its error names the line), `row` takes
/// a record in, with the record before it (`None` for the first). Where the input ends without a line end and its last record
/// cannot be read or `row` refuses it, that record is left out and the
/// warning saying so is returned.
pub(crate) fn each_record<R: Read>(
    reader: &mut csv::Reader<LastByte<R>>,
    read: impl Fn(&mut csv::Reader<LastByte<R>>, &mut csv::ByteRecord) -> Result<bool, LoadError>,
    mut row: impl FnMut(&csv::ByteRecord, Option<&csv::ByteRecord>) -> Result<(), LoadError>,
) -> Result<Option<String>, LoadError> {
    let left_out = |error: LoadError| {
        Some(format!(
            "{error}: the last line is left out: it has no line end, as when a logger stops in the middle of writing a row"
        ))
    };
    let mut record = csv::ByteRecord::new();
    let mut ahead = csv::ByteRecord::new();
    let mut before = csv::ByteRecord::new();
    let mut first = true;
    let mut current = read(reader, &mut record);
    loop {
        current = match current {
            Ok(false) => return Ok(None),
            Ok(true) => {
                let next = read(reader, &mut ahead);
                match row(&record, (!first).then_some(&before)) {
                    Err(e) if matches!(next, Ok(false)) && reader.get_ref().cut_short() => {
                        return Ok(left_out(e));
                    }
                    taken => taken?,
                }
                // before <- record <- ahead, and `ahead` free for the next read.
                std::mem::swap(&mut before, &mut record);
                std::mem::swap(&mut record, &mut ahead);
                first = false;
                next
            }
            Err(e) => match read(reader, &mut ahead) {
                Ok(false) if reader.get_ref().cut_short() => return Ok(left_out(e)),
                _ => return Err(e),
            },
        };
    }
}

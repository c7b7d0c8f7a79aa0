//! OME-TIFF, written by hand: a little-endian baseline TIFF, one uncompressed strip per plane,
//! one IFD per plane appended as the plane arrives, and the OME-XML in the first IFD's
//! ImageDescription. Why OME-TIFF rather than OME-Zarr: one file that every microscopy tool
//! opens (Fiji/Bio-Formats, tifffile, napari), no directory of chunks and no dependency to
//! write it, and appending a page keeps the file a valid TIFF after every frame — the IFD
//! chain is linked only once the page is on disk, and the XML's plane count is updated after
//! it, so an interrupted acquisition leaves a readable, complete prefix.

use crate::error::{Error, Result};
use specmux_io::exr::MAX_SAMPLES;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Pixel type of a file's planes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sample {
    U16,
    F32,
}

impl Sample {
    fn bytes(self) -> usize {
        match self {
            Sample::U16 => 2,
            Sample::F32 => 4,
        }
    }

    /// The OME Pixels Type.
    pub fn ome_type(self) -> &'static str {
        match self {
            Sample::U16 => "uint16",
            Sample::F32 => "float",
        }
    }
}

/// A TIFF being written page by page.
pub struct TiffWriter {
    file: File,
    path: PathBuf,
    width: usize,
    height: usize,
    sample: Sample,
    pages: usize,
    /// Where the pointer to the next IFD goes (the header's first, then each IFD's last).
    next_ptr_at: u64,
    /// Where the ImageDescription entry of the first IFD is, once written.
    desc_entry_at: Option<u64>,
    /// Where the description's bytes are and how many fit there.
    desc_at: u64,
    desc_capacity: usize,
    description: String,
    end: u64,
}

const TAG_DESCRIPTION: u16 = 270;

impl TiffWriter {
    /// A new file holding only the header; `reserve` bytes are kept for the description so that
    /// updates overwrite it in place.
    pub fn create(
        path: &Path,
        width: usize,
        height: usize,
        sample: Sample,
        reserve: usize,
    ) -> Result<TiffWriter> {
        let io = |e| Error::io(path, e);
        let mut file = File::create(path).map_err(io)?;
        file.write_all(&[b'I', b'I', 42, 0, 0, 0, 0, 0])
            .map_err(io)?;
        Ok(TiffWriter {
            file,
            path: path.to_path_buf(),
            width,
            height,
            sample,
            pages: 0,
            next_ptr_at: 4,
            desc_entry_at: None,
            desc_at: 0,
            desc_capacity: reserve.max(64),
            description: String::new(),
            end: 8,
        })
    }

    pub fn pages(&self) -> usize {
        self.pages
    }

    /// Append one plane (`width × height` samples, little-endian bytes): data, then its IFD,
    /// then the link from the previous IFD.
    pub fn append(&mut self, data: &[u8]) -> Result<()> {
        let expect = self.width * self.height * self.sample.bytes();
        if data.len() != expect || data.len() > u32::MAX as usize {
            return Err(Error::device(
                "recorder",
                format!(
                    "{}: a plane of {} bytes, expected {expect}",
                    self.path.display(),
                    data.len()
                ),
            ));
        }
        if self.end + data.len() as u64 + 4096 + self.desc_capacity as u64 > u32::MAX as u64 {
            return Err(Error::device(
                "recorder",
                format!(
                    "{}: a classic TIFF holds 4 GiB; the next plane does not fit",
                    self.path.display()
                ),
            ));
        }
        let first = self.pages == 0;
        if first {
            self.desc_at = self.end;
            let blank = vec![b' '; self.desc_capacity];
            self.write_at(self.desc_at, &blank)?;
            self.end += even(self.desc_capacity as u64);
        }
        let data_at = self.end;
        self.write_at(data_at, data)?;
        self.end += even(data.len() as u64);
        let ifd_at = self.end;
        let (ifd, desc_entry) = self.ifd(data_at, data.len() as u32, first);
        self.write_at(ifd_at, &ifd)?;
        self.end += ifd.len() as u64;
        if let Some(off) = desc_entry {
            self.desc_entry_at = Some(ifd_at + off);
        }
        self.write_at(self.next_ptr_at, &(ifd_at as u32).to_le_bytes())?;
        self.next_ptr_at = ifd_at + ifd.len() as u64 - 4;
        self.pages += 1;
        if first {
            let d = std::mem::take(&mut self.description);
            self.set_description(&d)?;
        }
        self.file.flush().map_err(|e| Error::io(&self.path, e))
    }

    /// The IFD of a page whose data is at `data_at`; the offset of its description entry.
    fn ifd(&self, data_at: u64, bytes: u32, first: bool) -> (Vec<u8>, Option<u64>) {
        let bits = (self.sample.bytes() * 8) as u32;
        let format = if self.sample == Sample::F32 { 3 } else { 1 };
        let mut entries: Vec<(u16, u16, u32, u32)> = vec![
            (256, 4, 1, self.width as u32),
            (257, 4, 1, self.height as u32),
            (258, 3, 1, bits),
            (259, 3, 1, 1),
            (262, 3, 1, 1),
            (273, 4, 1, data_at as u32),
            (277, 3, 1, 1),
            (278, 4, 1, self.height as u32),
            (279, 4, 1, bytes),
            (284, 3, 1, 1),
            (339, 3, 1, format),
        ];
        if first {
            entries.push((
                TAG_DESCRIPTION,
                2,
                self.desc_capacity as u32,
                self.desc_at as u32,
            ));
            entries.sort_by_key(|e| e.0);
        }
        let mut out = (entries.len() as u16).to_le_bytes().to_vec();
        let mut desc = None;
        for (i, (tag, ty, count, value)) in entries.into_iter().enumerate() {
            if tag == TAG_DESCRIPTION {
                desc = Some(2 + 12 * i as u64);
            }
            out.extend(tag.to_le_bytes());
            out.extend(ty.to_le_bytes());
            out.extend(count.to_le_bytes());
            // SHORT values sit in the first two bytes of the field.
            out.extend(value.to_le_bytes());
        }
        out.extend(0u32.to_le_bytes());
        (out, desc)
    }

    /// Replace the OME-XML: in place when it fits the reserved room (padded with spaces),
    /// else at the end of the file with the first IFD's entry pointed at it.
    pub fn set_description(&mut self, xml: &str) -> Result<()> {
        self.description = xml.to_string();
        let Some(entry) = self.desc_entry_at else {
            return Ok(());
        };
        let mut bytes = xml.as_bytes().to_vec();
        if bytes.len() + 1 > self.desc_capacity {
            self.desc_at = self.end;
            self.desc_capacity = bytes.len() + 1;
            self.end += even(self.desc_capacity as u64);
            let mut e = (self.desc_capacity as u32).to_le_bytes().to_vec();
            e.extend((self.desc_at as u32).to_le_bytes());
            self.write_at(entry + 4, &e)?;
        }
        bytes.resize(self.desc_capacity - 1, b' ');
        bytes.push(0);
        self.write_at(self.desc_at, &bytes)
    }

    fn write_at(&mut self, at: u64, bytes: &[u8]) -> Result<()> {
        let io = |e| Error::io(&self.path, e);
        self.file.seek(SeekFrom::Start(at)).map_err(io)?;
        self.file.write_all(bytes).map_err(io)
    }

    /// Flush to the disk.
    pub fn sync(&mut self) -> Result<()> {
        self.file.sync_all().map_err(|e| Error::io(&self.path, e))
    }
}

fn even(n: u64) -> u64 {
    n + (n & 1)
}

/// One page read back.
#[derive(Clone, Debug)]
pub struct Page {
    pub width: usize,
    pub height: usize,
    pub sample: Sample,
    /// Samples as f32 (u16 converted exactly).
    pub data: Vec<f32>,
}

/// Read a little-endian baseline TIFF of one strip per page, as this module writes: the first
/// page's ImageDescription and every page linked so far.
pub fn read(path: &Path) -> Result<(String, Vec<Page>)> {
    let mut bytes = Vec::new();
    File::open(path)
        .and_then(|mut f| f.read_to_end(&mut bytes))
        .map_err(|e| Error::io(path, e))?;
    parse(&bytes, path)
}

/// [`read`] over bytes already in memory; `path` names the file in errors. An IFD chain that
/// loops back on itself, or pages of more samples in all than the EXR reader takes
/// ([`MAX_SAMPLES`], 1 GiB of f32), are refused.
pub fn parse(bytes: &[u8], path: &Path) -> Result<(String, Vec<Page>)> {
    let bad = |why: &str| Error::device("recorder", format!("{}: {why}", path.display()));
    if bytes.len() < 8 || &bytes[..4] != b"II*\0" {
        return Err(bad("not a little-endian TIFF"));
    }
    let mut at = u32_at(bytes, 4).ok_or_else(|| bad("truncated header"))? as usize;
    let (mut description, mut pages) = (String::new(), Vec::new());
    let (mut seen, mut samples) = (std::collections::HashSet::new(), 0usize);
    while at != 0 {
        if !seen.insert(at) {
            return Err(bad(&format!("the IFD chain loops back to offset {at}")));
        }
        let (tags, next) = ifd(bytes, at).map_err(|why| bad(&why))?;
        if let Some(&(count, off)) = tags.get(&TAG_DESCRIPTION).filter(|_| pages.is_empty()) {
            let raw = bytes
                .get(off..off + count)
                .ok_or_else(|| bad("description beyond the end"))?;
            description = String::from_utf8_lossy(raw)
                .trim_end_matches(['\0', ' '])
                .to_string();
        }
        let page = page(bytes, &tags).map_err(|why| bad(&why))?;
        samples += page.data.len();
        if samples > MAX_SAMPLES {
            return Err(bad(&format!(
                "more than {MAX_SAMPLES} samples in {} pages: too large to read",
                pages.len() + 1
            )));
        }
        pages.push(page);
        at = next;
    }
    Ok((description, pages))
}

fn u16_at(b: &[u8], o: usize) -> Option<u16> {
    b.get(o..o + 2).map(|b| u16::from_le_bytes([b[0], b[1]]))
}

fn u32_at(b: &[u8], o: usize) -> Option<u32> {
    b.get(o..o + 4)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

type Tags = std::collections::HashMap<u16, (usize, usize)>;

/// The entries (tag → count, value) of the IFD at `at`, and the offset of the next IFD.
fn ifd(bytes: &[u8], at: usize) -> std::result::Result<(Tags, usize), String> {
    let n = u16_at(bytes, at).ok_or("IFD beyond the end")? as usize;
    let mut tags = Tags::new();
    for i in 0..n {
        let e = at + 2 + 12 * i;
        let (Some(tag), Some(ty), Some(count), Some(value)) = (
            u16_at(bytes, e),
            u16_at(bytes, e + 2),
            u32_at(bytes, e + 4),
            u32_at(bytes, e + 8),
        ) else {
            return Err("IFD entry beyond the end".into());
        };
        // A SHORT value sits in the first two bytes of the field.
        let value = if ty == 3 { value & 0xFFFF } else { value };
        tags.insert(tag, (count as usize, value as usize));
    }
    let next = u32_at(bytes, at + 2 + 12 * n).ok_or("next-IFD pointer beyond the end")?;
    Ok((tags, next as usize))
}

/// The plane an IFD describes.
fn page(bytes: &[u8], tags: &Tags) -> std::result::Result<Page, String> {
    let get = |t: u16| tags.get(&t).map(|v| v.1).ok_or(format!("tag {t} missing"));
    let (w, h, bits, off, len) = (get(256)?, get(257)?, get(258)?, get(273)?, get(279)?);
    let sample = match (bits, tags.get(&339).map_or(1, |v| v.1)) {
        (16, 1) => Sample::U16,
        (32, 3) => Sample::F32,
        (b, f) => return Err(format!("{b}-bit samples of format {f}")),
    };
    let raw = bytes
        .get(off..off.saturating_add(len))
        .filter(|r| Some(r.len()) == w.checked_mul(h).and_then(|p| p.checked_mul(sample.bytes())))
        .ok_or("strip beyond the end or of the wrong size")?;
    let data = match sample {
        Sample::U16 => raw
            .chunks_exact(2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]) as f32)
            .collect(),
        Sample::F32 => raw
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
            .collect(),
    };
    Ok(Page {
        width: w,
        height: h,
        sample,
        data,
    })
}

/// What the OME-XML of one image says.
pub struct OmeImage<'a> {
    pub name: &'a str,
    pub width: usize,
    pub height: usize,
    pub sample: Sample,
    /// Channel names (SizeC); planes run over C then T.
    pub channels: &'a [String],
    pub size_t: usize,
    /// Per plane: (seconds since the first, exposure seconds); empty to leave out Plane elements.
    pub planes: &'a [(f64, f64)],
    /// Key–value pairs of a MapAnnotation (settings, calibration, files beside it).
    pub annotations: &'a [(String, String)],
}

/// Escape text for XML attributes and content.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The OME-XML (2016-06 schema) of one image stored in this file's IFDs from 0.
pub fn ome_xml(img: &OmeImage) -> String {
    let c = img.channels.len().max(1);
    let mut x = format!(
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<OME xmlns=\"http://www.openmicroscopy.org/Schemas/OME/2016-06\" \
         Creator=\"specmux-controller\">\n<Image ID=\"Image:0\" Name=\"{}\">\n<Pixels ID=\"Pixels:0\" DimensionOrder=\"XYCZT\" \
         Type=\"{}\" SizeX=\"{}\" SizeY=\"{}\" SizeC=\"{c}\" SizeZ=\"1\" SizeT=\"{}\" BigEndian=\"false\">\n",
        esc(img.name), img.sample.ome_type(), img.width, img.height, img.size_t
    );
    for (i, name) in img.channels.iter().enumerate() {
        x += &format!(
            "<Channel ID=\"Channel:0:{i}\" Name=\"{}\" SamplesPerPixel=\"1\"/>\n",
            esc(name)
        );
    }
    x += &format!("<TiffData IFD=\"0\" PlaneCount=\"{}\"/>\n", c * img.size_t);
    for (p, (dt, exp)) in img.planes.iter().enumerate() {
        x += &format!(
            "<Plane TheC=\"{}\" TheZ=\"0\" TheT=\"{}\" DeltaT=\"{dt:.9}\" DeltaTUnit=\"s\" ExposureTime=\"{exp}\" ExposureTimeUnit=\"s\"/>\n",
            p % c, p / c
        );
    }
    x += "</Pixels>\n";
    if !img.annotations.is_empty() {
        x += "<AnnotationRef ID=\"Annotation:0\"/>\n";
    }
    x += "</Image>\n";
    if !img.annotations.is_empty() {
        x += "<StructuredAnnotations>\n<MapAnnotation ID=\"Annotation:0\" Namespace=\"specmux\">\n<Value>\n";
        for (k, v) in img.annotations {
            x += &format!("<M K=\"{}\">{}</M>\n", esc(k), esc(v));
        }
        x += "</Value>\n</MapAnnotation>\n</StructuredAnnotations>\n";
    }
    x + "</OME>\n"
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh scratch folder's guard (it removes the folder on drop) and `t.ome.tif` in it.
    fn tmp(name: &str) -> (tempfile::TempDir, PathBuf) {
        let d = tempfile::Builder::new()
            .prefix(&format!("specmux-ome-{name}-"))
            .tempdir()
            .unwrap();
        let path = d.path().join("t.ome.tif");
        (d, path)
    }

    #[test]
    fn every_prefix_is_a_valid_tiff_and_the_description_grows_past_its_room() {
        let (_scratch, path) = tmp("prefix");
        let mut w = TiffWriter::create(&path, 3, 2, Sample::U16, 80).unwrap();
        w.set_description("<a/>").unwrap();
        for k in 0..4u16 {
            let plane: Vec<u8> = (0..6u16).flat_map(|v| (v + 10 * k).to_le_bytes()).collect();
            w.append(&plane).unwrap();
            let (desc, pages) = read(&path).unwrap();
            assert_eq!(pages.len(), k as usize + 1);
            assert_eq!(pages[k as usize].data[5], (5 + 10 * k) as f32);
            assert_eq!(desc, "<a/>");
        }
        let long = "x".repeat(500);
        w.set_description(&long).unwrap();
        let (desc, pages) = read(&path).unwrap();
        assert_eq!((desc, pages.len()), (long, 4));
    }

    #[test]
    fn float_planes_round_trip_and_garbage_is_refused() {
        let (_scratch, path) = tmp("float");
        let mut w = TiffWriter::create(&path, 2, 2, Sample::F32, 64).unwrap();
        let v = [1.5f32, -2.25, 3.0e-7, 4096.0];
        w.append(&v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<_>>())
            .unwrap();
        assert!(w.append(&[0u8; 3]).is_err());
        let (_, pages) = read(&path).unwrap();
        assert_eq!(pages[0].data, v.to_vec());
        std::fs::write(&path, b"II*\0\xff\xff\xff\x7f").unwrap();
        assert!(read(&path)
            .unwrap_err()
            .to_string()
            .contains("beyond the end"));
        std::fs::write(&path, b"MM\0*").unwrap();
        assert!(read(&path).is_err());
    }

    /// A file of one 2×2 u16 page whose IFD's next pointer is `next(ifd offset)`.
    fn one_page_linked_to(name: &str, next: impl Fn(u32) -> u32) -> Vec<u8> {
        let (_scratch, path) = tmp(name);
        let mut w = TiffWriter::create(&path, 2, 2, Sample::U16, 64).unwrap();
        w.append(&[1, 0, 2, 0, 3, 0, 4, 0]).unwrap();
        let mut b = std::fs::read(&path).unwrap();
        let at = u32_at(&b, 4).unwrap();
        let n = u16_at(&b, at as usize).unwrap() as usize;
        let link = at as usize + 2 + 12 * n;
        b[link..link + 4].copy_from_slice(&next(at).to_le_bytes());
        b
    }

    #[test]
    fn an_ifd_chain_that_loops_is_refused_naming_the_offset() {
        let b = one_page_linked_to("loop", |at| at);
        let at = u32_at(&b, 4).unwrap();
        let e = parse(&b, Path::new("f.ome.tif")).unwrap_err().to_string();
        assert!(e.contains(&format!("loops back to offset {at}")), "{e}");
        assert_eq!(e.lines().count(), 1);
        // Linked to nothing, the same bytes read as one page.
        let (_, pages) = parse(&one_page_linked_to("end", |_| 0), Path::new("f")).unwrap();
        assert_eq!(pages[0].data, vec![1.0, 2.0, 3.0, 4.0]);
    }

    #[test]
    fn ome_xml_names_planes_and_escapes() {
        let chans = vec!["dark".to_string(), "a<b".to_string()];
        let ann = vec![("k&".to_string(), "\"v\"".to_string())];
        let x = ome_xml(&OmeImage {
            name: "n",
            width: 4,
            height: 3,
            sample: Sample::F32,
            channels: &chans,
            size_t: 1,
            planes: &[],
            annotations: &ann,
        });
        assert!(
            x.contains("SizeC=\"2\"")
                && x.contains("Type=\"float\"")
                && x.contains("PlaneCount=\"2\""),
            "{x}"
        );
        assert!(
            x.contains("a&lt;b") && x.contains("k&amp;") && x.contains("&quot;v&quot;"),
            "{x}"
        );
    }
}

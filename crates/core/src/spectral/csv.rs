//! Reader for the spectral CSV files in `spectra/`: `#` comment lines (the first is the
//! provenance), a header `wavelength_nm,<name>…`, then one row per wavelength.

use crate::error::Error;
use crate::error::Result;
use crate::spectral::curve::Curve;
use std::path::Path;

/// A table of curves sharing one wavelength column, with the file's provenance line.
#[derive(Clone, Debug)]
pub struct Table {
    pub provenance: String,
    pub curves: Vec<Curve>,
}

/// Parse a spectral CSV from text; `path` is used only in error messages.
pub fn parse(path: &Path, text: &str) -> Result<Table> {
    let err = |line: usize, msg: String| Error::Csv {
        path: path.to_path_buf(),
        line,
        msg,
    };
    let mut provenance = String::new();
    let mut header: Option<Vec<String>> = None;
    let mut rows: Vec<Vec<f64>> = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line_no = i + 1;
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        if let Some(c) = line.strip_prefix('#') {
            if provenance.is_empty() {
                provenance = c
                    .trim()
                    .trim_start_matches("provenance:")
                    .trim()
                    .to_string();
            }
            continue;
        }
        let cells: Vec<&str> = line.split(',').map(str::trim).collect();
        match &header {
            None => {
                if cells[0] != "wavelength_nm" {
                    return Err(err(
                        line_no,
                        format!(
                            "header must start with `wavelength_nm`, found `{}`",
                            cells[0]
                        ),
                    ));
                }
                if cells.len() < 2 {
                    return Err(err(line_no, "header names no curve column".into()));
                }
                header = Some(cells[1..].iter().map(|s| s.to_string()).collect());
            }
            Some(h) => {
                if cells.len() != h.len() + 1 {
                    return Err(err(
                        line_no,
                        format!("{} cells, header has {}", cells.len(), h.len() + 1),
                    ));
                }
                let mut row = Vec::with_capacity(cells.len());
                for (c, cell) in cells.iter().enumerate() {
                    let field = if c == 0 { "wavelength_nm" } else { &h[c - 1] };
                    let v: f64 = cell.parse().map_err(|_| {
                        err(line_no, format!("`{field}`: `{cell}` is not a number"))
                    })?;
                    if !v.is_finite() {
                        return Err(err(line_no, format!("`{field}`: {cell} is not finite")));
                    }
                    row.push(v);
                }
                if let Some(prev) = rows
                    .last()
                    .map(|r: &Vec<f64>| r[0])
                    .filter(|&p| row[0] <= p)
                {
                    let why = format!("wavelengths must increase: {} nm follows {prev} nm", row[0]);
                    return Err(err(line_no, why));
                }
                rows.push(row);
            }
        }
    }
    let header = header.ok_or_else(|| err(0, "no header line `wavelength_nm,…`".into()))?;
    if provenance.is_empty() {
        return Err(err(1, "missing `# provenance:` line".into()));
    }
    let wl: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    let curves = header
        .iter()
        .enumerate()
        .map(|(c, name)| {
            let v = rows.iter().map(|r| r[c + 1]).collect();
            Curve::new(name.clone(), wl.clone(), v).map_err(|e| err(0, e.to_string()))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(Table { provenance, curves })
}

/// Read and parse a spectral CSV file.
pub fn read(path: &Path) -> Result<Table> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    parse(path, &text)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(text: &str) -> Result<Table> {
        parse(Path::new("t.csv"), text)
    }

    #[test]
    fn reads_two_curves() {
        let t = p("# provenance: test\nwavelength_nm,a,b\n400,0.1,1\n500,0.2,2\n").unwrap();
        assert_eq!(t.provenance, "test");
        assert_eq!(t.curves.len(), 2);
        assert_eq!(t.curves[1].eval(450.0), 1.5);
    }

    #[test]
    fn malformed_rows_name_line_and_field() {
        let e = p("# provenance: x\nwavelength_nm,a\n400,0.1\n500,zz\n").unwrap_err();
        let s = e.to_string();
        assert!(
            s.contains("t.csv:4") && s.contains("`a`") && s.contains("zz"),
            "{s}"
        );
        let e = p("# provenance: x\nwavelength_nm,a\n400,NaN\n500,1\n").unwrap_err();
        assert!(e.to_string().contains("not finite"));
        let e = p("# provenance: x\nwavelength_nm,a\n500,1\n\n400,1\n").unwrap_err();
        assert!(
            e.to_string().contains("t.csv:5") && e.to_string().contains("increase"),
            "{e}"
        );
        assert!(p("wavelength_nm,a\n400,1\n500,1\n").is_err());
        assert!(p("# provenance: x\nnm,a\n400,1\n").is_err());
    }
}

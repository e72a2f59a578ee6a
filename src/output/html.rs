//! Pieces of the self-contained HTML pages strand writes (`strand compare --report`, the plan's
//! report): text escaped for HTML, a table of formatted cells, and a PNG embedded in the page as a
//! data URI, so that a page needs no file beside it and nothing fetched from elsewhere.

use base64::Engine as _;
use std::fmt::Write as _;
use std::path::Path;

/// Text for HTML content or a quoted attribute.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for ch in s.chars() {
        match ch {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(ch),
        }
    }
    out
}

/// A table of already-formatted cells, escaped here; a flagged row has the class `flag_class`.
pub fn table(s: &mut String, header: &[&str], flag_class: &str, rows: impl IntoIterator<Item = (bool, Vec<String>)>) {
    s.push_str("<table>\n<tr>");
    for h in header {
        let _ = write!(s, "<th>{}</th>", escape(h));
    }
    s.push_str("</tr>\n");
    for (flagged, cells) in rows {
        if flagged {
            let _ = write!(s, "<tr class=\"{}\">", escape(flag_class));
        } else {
            s.push_str("<tr>");
        }
        for c in cells {
            let _ = write!(s, "<td>{}</td>", escape(&c));
        }
        s.push_str("</tr>\n");
    }
    s.push_str("</table>\n");
}

/// The PNG at `png` as a figure whose image is in the page itself (a data URI), with `caption`.
pub fn embedded_png(png: &Path, caption: &str) -> std::io::Result<String> {
    let bytes = std::fs::read(png)?;
    let data = base64::engine::general_purpose::STANDARD.encode(bytes);
    Ok(format!("<figure><img src=\"data:image/png;base64,{data}\" alt=\"{0}\"><figcaption>{0}</figcaption></figure>\n", escape(caption)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_png_is_embedded_whole_and_text_is_escaped() {
        let dir = tempfile::tempdir().unwrap();
        let png = dir.path().join("a.png");
        std::fs::write(&png, b"\x89PNG\r\n\x1a\nfoobar").unwrap();
        let f = embedded_png(&png, "a < b").unwrap();
        // RFC 4648's vector: "foobar" is "Zm9vYmFy"; the signature's 8 bytes come first
        assert!(f.contains("src=\"data:image/png;base64,iVBORw0KGgpmb29iYXI=\"") && f.contains("alt=\"a &lt; b\""), "{f}");
        assert!(embedded_png(&dir.path().join("none.png"), "x").is_err());
        let mut s = String::new();
        table(&mut s, &["a", "b"], "flag", [(true, vec!["1".into(), "<2>".into()]), (false, vec!["3".into(), "4".into()])]);
        assert_eq!(s, "<table>\n<tr><th>a</th><th>b</th></tr>\n<tr class=\"flag\"><td>1</td><td>&lt;2&gt;</td></tr>\n<tr><td>3</td><td>4</td></tr>\n</table>\n");
    }
}

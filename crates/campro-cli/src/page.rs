//! The report pages' shared layout (`inspect`'s index and `check`'s report): one stylesheet,
//! captioned figures and a lightbox, all plain HTML and CSS. The pages carry no script, so a
//! hostile file name, escaped by [`html_escape`], can never run anything in them.

use std::path::Path;

/// The stylesheet of both pages: figures in rows that wrap, captions under them, flagged rows
/// tinted, and the lightbox (`:target`) over everything.
pub const STYLE: &str = "body{font-family:system-ui,sans-serif;margin:1.5em;max-width:110em;color:#222}\
table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;padding:.3em .5em;text-align:left;vertical-align:top}\
.face{color:#b0b}.person{color:#070}.link,.warn{color:#b00;font-weight:bold}.safe{color:#070}.lost{color:#a60}\
.verdict{font-family:monospace}#summary{font-size:1.15em;padding:.6em .8em;background:#f4f4f4;border-left:.4em solid #888}\
#summary.alarm{border-left-color:#b00;background:#fee}\
section.row{margin:1.2em 0;padding:.6em;border:1px solid #ddd;border-radius:.3em}section.row.flag{border:2px solid #b00;background:#fff6f6}\
section.row h2{font-size:1em;margin:.1em 0 .5em;word-break:break-all}\
.figs{display:flex;flex-wrap:wrap;gap:.8em;align-items:flex-start}\
figure{margin:0;flex:1 1 20em;max-width:34em}figure.crop{flex:0 0 15em;max-width:15em}\
figure a{display:block}figcaption{font-size:.9em;padding:.25em 0}\
.clip{overflow:hidden;background:#000}.clip img{display:block;max-width:none;height:auto}\
figure.crop img{width:112px;height:112px;image-rendering:pixelated;display:block}\
.lb{display:none}.lb:target{display:block;position:fixed;inset:0;z-index:9;background:rgba(0,0,0,.92);overflow:auto;padding:1em}\
.lb img{max-width:none;display:inline-block;margin:0 .3em}.lb>a{display:block;text-align:center}.lb p{color:#eee;text-align:center}.lb a{color:#eee}";

/// The page's start: doctype, title (escaped) and [`STYLE`].
pub fn head(title: &str) -> String {
    format!(
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <meta name=\"viewport\" content=\"width=device-width,initial-scale=1\"><title>{}</title>\n\
         <style>{STYLE}</style></head><body>\n",
        html_escape(title)
    )
}

/// One panel of a picture that holds `panels` panels of `w`x`h` pixels side by side, `gap`
/// pixels apart: a figure showing panel `k` alone (the picture cropped by CSS, so one file
/// serves every panel), linked to the lightbox `zoom` (an element id), with `caption` (HTML,
/// already escaped) under it.
#[allow(clippy::too_many_arguments)]
pub fn panel(
    src: &str,
    alt: &str,
    (w, h): (u32, u32),
    gap: u32,
    panels: usize,
    k: usize,
    zoom: &str,
    caption: &str,
) -> String {
    let whole = (panels as f64 * w as f64 + panels.saturating_sub(1) as f64 * gap as f64) / w.max(1) as f64 * 100.0;
    let shift = k as f64 * (w + gap) as f64 / w.max(1) as f64 * 100.0;
    format!(
        "<figure><a href=\"#{zoom}\"><div class=\"clip\" style=\"aspect-ratio:{w}/{h}\">\
         <img src=\"{src}\" alt=\"{}\" style=\"width:{whole:.4}%;margin-left:-{shift:.4}%\"></div></a>\
         <figcaption>{caption}</figcaption></figure>",
        html_escape(alt)
    )
}

/// A small figure (a face crop) with its caption (HTML, already escaped), linked to the
/// lightbox `zoom`.
pub fn crop(src: &str, alt: &str, zoom: &str, caption: &str) -> String {
    format!(
        "<figure class=\"crop\"><a href=\"#{zoom}\"><img src=\"{src}\" alt=\"{}\"></a><figcaption>{caption}</figcaption></figure>",
        html_escape(alt)
    )
}

/// The lightbox `id`: `body` (HTML: pictures made by [`big`]) over the page, scrolling when
/// larger, with `caption` (HTML, already escaped) above; a click on it goes back to the
/// element `back`.
pub fn lightbox(id: &str, caption: &str, body: &str, back: &str) -> String {
    format!("<div class=\"lb\" id=\"{id}\"><p>{caption} <a href=\"#{back}\">close</a></p><a href=\"#{back}\">{body}</a></div>")
}

/// A picture for a [`lightbox`]: at its own size, or `width` CSS pixels wide (small crops
/// enlarged without smoothing); loaded only when the box is opened.
pub fn big(src: &str, alt: &str, width: Option<u32>) -> String {
    let w = width.map(|w| format!(" style=\"width:{w}px;image-rendering:pixelated\"")).unwrap_or_default();
    format!("<img src=\"{src}\" alt=\"{}\" loading=\"lazy\"{w}>", html_escape(alt))
}

/// What a URL path segment keeps as is: RFC 3986's unreserved characters.
const SEGMENT: &percent_encoding::AsciiSet =
    &percent_encoding::NON_ALPHANUMERIC.remove(b'-').remove(b'.').remove(b'_').remove(b'~');

/// `path` relative to `root` as a URL path (each segment percent-encoded).
pub fn href(path: &Path, root: &Path) -> String {
    let rel = path.strip_prefix(root).unwrap_or(path);
    rel.components()
        .map(|c| percent_encoding::utf8_percent_encode(&c.as_os_str().to_string_lossy(), SEGMENT).to_string())
        .collect::<Vec<_>>()
        .join("/")
}

/// What `inspect` and `check` each count, said on both pages so their numbers tell one story
/// (plain text; escape it for HTML).
pub const ONE_STORY: &str = "inspect and check look at the same photos from two sides. inspect (campro inspect, inspect/index.html) counts the faces a face detector still finds after the camera: a face found is a face a system could try to recognise. check (campro check, report/index.html) asks the next question: can a face-recognition model match each face to its own person? So inspect's count is the larger one: a face can still be found and yet match no one, and a face no detector finds is still scored by check, which looks where the raw face was.";

/// `text` safe inside HTML text and double-quoted attributes.
pub fn html_escape(text: &str) -> String {
    let mut s = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => s.push_str("&amp;"),
            '<' => s.push_str("&lt;"),
            '>' => s.push_str("&gt;"),
            '"' => s.push_str("&quot;"),
            '\'' => s.push_str("&#39;"),
            c if c.is_control() => s.push('\u{fffd}'),
            c => s.push(c),
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_panel_crops_its_part_of_the_picture() {
        // Three 100-px panels 8 px apart: 316 px in all, 316% of one panel; the third starts
        // at 216 px, 216% of a panel to the left.
        let f = panel("a.png", "a", (100, 50), 8, 3, 2, "z1", "enhanced");
        assert!(f.contains("width:316.0000%;margin-left:-216.0000%"), "{f}");
        assert!(f.contains("aspect-ratio:100/50") && f.contains("href=\"#z1\""), "{f}");
    }

    #[test]
    fn text_is_escaped_and_hrefs_encoded() {
        assert_eq!(html_escape("<img src=x onerror='a'>&\""), "&lt;img src=x onerror=&#39;a&#39;&gt;&amp;&quot;");
        assert_eq!(href(Path::new("/o/a b/c#?.png"), Path::new("/o")), "a%20b/c%23%3F.png");
        assert!(big("p.png", "<x>", None).contains("alt=\"&lt;x&gt;\""));
        assert!(lightbox("z", "cap", "", "r").contains("id=\"z\""));
    }
}

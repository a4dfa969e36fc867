//! Reading screenshots: the page decodes the PNG the driver took and measures
//! the 3D canvas's part of it, so the check is on what was really drawn.

use serde_json::{Value, json};

use crate::webdriver::Browser;

/// Counts in the canvas area of `png`: `saturated` pixels (skeleton colours;
/// the ground, grid and sky are grey) and `colors` (distinct 12-bit colours).
pub async fn canvas_stats(browser: &Browser, png: &str) -> Value {
    browser
        .eval_async(
            r#"
            const [b64, done] = [arguments[0], arguments[arguments.length - 1]];
            const r = document.querySelector('#stage canvas').getBoundingClientRect();
            const img = new Image();
            img.onload = () => {
              const c = document.createElement('canvas');
              c.width = Math.round(r.width); c.height = Math.round(r.height);
              const g = c.getContext('2d');
              g.drawImage(img, r.left, r.top, r.width, r.height, 0, 0, c.width, c.height);
              const d = g.getImageData(0, 0, c.width, c.height).data;
              let saturated = 0; const colors = new Set();
              for (let i = 0; i < d.length; i += 4) {
                const mx = Math.max(d[i], d[i + 1], d[i + 2]), mn = Math.min(d[i], d[i + 1], d[i + 2]);
                if (mx - mn > 60) saturated++;
                colors.add(((d[i] >> 4) << 8) | ((d[i + 1] >> 4) << 4) | (d[i + 2] >> 4));
              }
              done({ saturated, colors: colors.size, pixels: d.length / 4 });
            };
            img.onerror = () => done({ error: 'not a PNG' });
            img.src = 'data:image/png;base64,' + b64;
            "#,
            vec![json!(png)],
        )
        .await
}

/// Pixels of the canvas area that differ (any channel by more than 24) between two screenshots.
pub async fn canvas_diff(browser: &Browser, a: &str, b: &str) -> u64 {
    browser
        .eval_async(
            r#"
            const [a, b, done] = [arguments[0], arguments[1], arguments[arguments.length - 1]];
            const r = document.querySelector('#stage canvas').getBoundingClientRect();
            const load = (s) => new Promise((ok) => { const i = new Image(); i.onload = () => ok(i); i.src = 'data:image/png;base64,' + s; });
            Promise.all([load(a), load(b)]).then(([x, y]) => {
              const px = (img) => {
                const c = document.createElement('canvas');
                c.width = Math.round(r.width); c.height = Math.round(r.height);
                const g = c.getContext('2d');
                g.drawImage(img, r.left, r.top, r.width, r.height, 0, 0, c.width, c.height);
                return g.getImageData(0, 0, c.width, c.height).data;
              };
              const [p, q] = [px(x), px(y)];
              let n = 0;
              for (let i = 0; i < p.length; i += 4) {
                if (Math.abs(p[i] - q[i]) > 24 || Math.abs(p[i + 1] - q[i + 1]) > 24 || Math.abs(p[i + 2] - q[i + 2]) > 24) n++;
              }
              done(n);
            });
            "#,
            vec![json!(a), json!(b)],
        )
        .await
        .as_u64()
        .expect("a count")
}

/// Pixels of `color` (`[r, g, b]`, within 40 per channel) in the canvases under `selector`.
pub async fn colored_pixels(browser: &Browser, selector: &str, color: [u8; 3]) -> u64 {
    browser
        .eval(
            r#"
            const [sel, rgb] = arguments;
            let n = 0;
            for (const c of document.querySelectorAll(sel)) {
              const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
              for (let i = 0; i < d.length; i += 4) {
                if (d[i + 3] > 0 && Math.abs(d[i] - rgb[0]) < 40 && Math.abs(d[i + 1] - rgb[1]) < 40 && Math.abs(d[i + 2] - rgb[2]) < 40) n++;
              }
            }
            return n;
            "#,
            vec![json!(selector), json!(color)],
        )
        .await
        .as_u64()
        .expect("a count")
}

/// Writes the screenshot to `$MOTIONAUG_SCREENSHOTS/<name>.png` when that is set
/// (how the pictures in docs/ are made).
pub fn save(png: &str, name: &str) {
    use base64::Engine;
    if let Some(dir) = std::env::var_os("MOTIONAUG_SCREENSHOTS") {
        let bytes = base64::engine::general_purpose::STANDARD
            .decode(png)
            .expect("base64 PNG");
        std::fs::write(
            std::path::Path::new(&dir).join(format!("{name}.png")),
            bytes,
        )
        .expect("screenshot written");
    }
}

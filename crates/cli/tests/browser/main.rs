//! The viewer in a real headless Chromium (one test binary): `motionaug view`
//! on an augment output and a correction, and the coordinator's `/viewer/`
//! for a tenant's dataset and a running augmentation. The two tests take
//! turns (one browser at a time on small machines).

#[path = "../common/mod.rs"]
mod common;
mod local;
mod pixels;
mod service;
mod webdriver;

/// One browser test at a time.
pub async fn serial() -> tokio::sync::MutexGuard<'static, ()> {
    static LOCK: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());
    LOCK.lock().await
}

/// The viewer was built (Node.js and npm were there): the tests need the page.
pub fn bundled() {
    assert!(
        viewer::assets::bundled(),
        "the viewer page was not built: {}",
        viewer::assets::MISSING_BECAUSE
    );
}

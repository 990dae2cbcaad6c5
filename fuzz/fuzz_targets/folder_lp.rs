//! Any text as the `dirs.lp` of an RTI folder holding two small images (`a.png`, `b.png`) with a
//! secret file beside the folder: an error or a BTF, never a panic, and never an image read
//! from outside the folder (the secret's marker size, 3 x 5, must never be seen).
//! Run: `scripts/fuzz folder_lp` (or `cargo fuzz run folder_lp`).
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;

/// The folder `root/set` (images and the fuzzed `dirs.lp`) and `root/secret.png` (3 x 5).
fn set() -> &'static PathBuf {
    static SET: OnceLock<PathBuf> = OnceLock::new();
    SET.get_or_init(|| {
        let base = std::env::var_os("BTFMRF_FUZZ_TMP").unwrap_or("/tmp".into());
        let root = tempfile::tempdir_in(base).expect("a folder").keep();
        let set = root.join("set");
        std::fs::create_dir(&set).expect("made");
        let png = |w, h| {
            let img = ndarray::Array3::from_elem((3, h, w), 0.3f32);
            btfmrf::btf::io::picture::encode(&img, btfmrf::btf::ImageFormat::Png, "x").unwrap()
        };
        std::fs::write(set.join("a.png"), png(4, 4)).unwrap();
        std::fs::write(set.join("b.png"), png(4, 4)).unwrap();
        std::fs::write(root.join("secret.png"), png(3, 5)).unwrap();
        set
    })
}

fuzz_target!(|data: &[u8]| {
    let set = set();
    std::fs::write(set.join("dirs.lp"), data).expect("written");
    if let Ok(btf) = btfmrf::btf::Btf::open(set) {
        assert_eq!((btf.width(), btf.height()), (4, 4), "an image from outside the folder");
        let _ = btf.image(0, 0);
    }
});

//! Writing a whole BTF in the layout its directions allow: UBO2003 names where every
//! direction is in whole degrees, an RTI capture (images and a `.lp` file with the exact
//! light vectors) for one view at the zenith otherwise.

use std::path::Path;

use super::{ImageFormat, rti, ubo2003};
use crate::btf::dataset::Btf;
use crate::btf::error::{BtfError, Result};
use crate::progress::Progress;

/// Writes `btf` as a zip archive (`out` ending in `.zip`) or a new folder: the UBO2003 layout
/// ([`ubo2003::write_ubo2003`]) when every view and light is in whole degrees, else the RTI
/// layout ([`rti::write_rti`]) when it has one view at the zenith (an RTI capture, or a model
/// of one). The output appears only when complete.
///
/// # Errors
/// Directions neither layout can name (several views, not all in whole degrees), unreadable
/// source images, an existing output folder, or an unwritable destination.
pub fn write_btf(
    btf: &Btf,
    out: &Path,
    format: ImageFormat,
    progress: &dyn Progress,
) -> Result<()> {
    if ubo2003::has_whole_degrees(btf) {
        ubo2003::write_ubo2003(btf, out, format, progress)
    } else if rti::is_fixed_view(btf) {
        rti::write_rti(btf, out, format, progress)
    } else {
        Err(BtfError::parameter(
            "directions",
            format!(
                "{} views and {} lights, not all in whole degrees: the UBO2003 names need whole \
                 degrees and an RTI capture holds one view at the zenith",
                btf.views().len(),
                btf.lights().len()
            ),
        ))
    }
}

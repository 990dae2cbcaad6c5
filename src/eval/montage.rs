//! Side-by-side sheets of images, for eyeballing methods against measurements in reports.

use ndarray::{Array3, s};

/// Lays out rows of planar `(3, h, w)` images on a white sheet with `gap` pixels between
/// them; each image is enlarged by pixel repetition to the height of the tallest image of the
/// whole sheet (when that is a whole multiple of its own height), so small measurements and
/// large syntheses compare at one scale.
pub fn montage(rows: &[Vec<&Array3<f32>>], gap: usize) -> Array3<f32> {
    let height = rows
        .iter()
        .flatten()
        .map(|im| im.dim().1)
        .max()
        .unwrap_or(0);
    let scaled: Vec<Vec<Array3<f32>>> = rows
        .iter()
        .map(|row| row.iter().map(|im| enlarge(im, height)).collect())
        .collect();
    let width = scaled
        .iter()
        .map(|row| row.iter().map(|im| im.dim().2 + gap).sum::<usize>())
        .max()
        .unwrap_or(0)
        .saturating_sub(gap);
    let total = (rows.len() * (height + gap)).saturating_sub(gap);
    let mut sheet = Array3::<f32>::ones((3, total, width));
    for (r, row) in scaled.iter().enumerate() {
        let mut x = 0;
        for im in row {
            let (_, h, w) = im.dim();
            let y = r * (height + gap);
            sheet.slice_mut(s![.., y..y + h, x..x + w]).assign(im);
            x += w + gap;
        }
    }
    sheet
}

/// Enlarges by pixel repetition to `height` when that is a whole multiple of the image's.
fn enlarge(image: &Array3<f32>, height: usize) -> Array3<f32> {
    let (_, h, w) = image.dim();
    let f = if h > 0 && height.is_multiple_of(h) {
        height / h
    } else {
        1
    };
    Array3::from_shape_fn((3, h * f, w * f), |(c, y, x)| image[[c, y / f, x / f]])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn panels_are_enlarged_to_one_height_and_separated_by_white() {
        let small = Array3::from_elem((3, 2, 2), 0.25f32);
        let big = Array3::from_elem((3, 4, 3), 0.5f32);
        let sheet = montage(&[vec![&small, &big], vec![&big]], 1);
        // Heights: 4 per row, 1 gap between the two rows; widths: 4 + 1 + 3.
        assert_eq!(sheet.dim(), (3, 9, 8));
        assert_eq!(sheet[[0, 3, 3]], 0.25); // the small image, doubled
        assert_eq!(sheet[[0, 0, 4]], 1.0); // the gap
        assert_eq!(sheet[[1, 0, 5]], 0.5); // the big image
        assert_eq!(sheet[[2, 4, 0]], 1.0); // the gap between rows
        assert_eq!(sheet[[2, 5, 0]], 0.5); // second row
        assert_eq!(sheet[[2, 5, 4]], 1.0); // second row is shorter: white
        assert_eq!(montage(&[], 3).dim(), (3, 0, 0));
    }
}

use opencv::core::{CV_8UC1, CV_16UC1, Mat, Scalar, Vector};

use super::*;

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("png_dir_{name}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn png(path: &Path, typ: i32, value: f64) {
    let m = Mat::new_rows_cols_with_default(3, 4, typ, Scalar::all(value)).unwrap();
    assert!(opencv::imgcodecs::imwrite(&*path.to_string_lossy(), &m, &Vector::new()).unwrap());
}

#[test]
fn sixteen_bit_pngs_play_in_file_name_order_and_others_are_named() {
    let d = dir("order");
    png(&d.join("b.png"), CV_16UC1, 2000.0);
    png(&d.join("a.png"), CV_16UC1, 1000.0);
    png(&d.join("c.png"), CV_8UC1, 7.0);
    std::fs::write(d.join("notes.txt"), "not an image").unwrap();
    let mut p = PngDir::open(&d).unwrap();
    assert_eq!(p.len(), 3);
    let mut image = DepthImage::default();
    p.next_image(&mut image).unwrap().unwrap();
    assert_eq!((image.width, image.height), (4, 3));
    assert_eq!(image.depths, vec![1000; 12]);
    p.next_image(&mut image).unwrap().unwrap();
    assert_eq!(image.depths, vec![2000; 12]);
    let err = p.next_image(&mut image).unwrap().unwrap_err();
    assert!(
        err.to_string()
            .contains("not a 16-bit single-channel image"),
        "{err}"
    );
    assert!(p.next_image(&mut image).is_none());
    p.rewind();
    p.next_image(&mut image).unwrap().unwrap();
    assert_eq!(image.depths, vec![1000; 12]);
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn a_directory_without_pngs_is_refused_naming_it() {
    let d = dir("empty");
    let err = PngDir::open(&d).err().unwrap();
    assert_eq!(err.to_string(), format!("{}: no .png files", d.display()));
    std::fs::remove_dir_all(&d).unwrap();
}

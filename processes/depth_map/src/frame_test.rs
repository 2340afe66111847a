use super::*;

fn k() -> Intrinsics {
    Intrinsics {
        fx: 100.0,
        fy: 100.0,
        cx: 1.5,
        cy: 1.0,
    }
}

#[test]
fn a_consistent_frame_is_accepted() {
    let d = [1000u16; 12];
    let v = DepthView::new(
        4,
        3,
        k(),
        DepthPixels::U16 {
            data: &d,
            scale_m: 0.001,
        },
    )
    .unwrap();
    assert_eq!((v.width(), v.height(), v.pixels().len()), (4, 3, 12));
}

#[test]
fn a_payload_shorter_or_longer_than_the_header_says_is_refused() {
    let d = [0u16; 11];
    let e = DepthView::new(
        4,
        3,
        k(),
        DepthPixels::U16 {
            data: &d,
            scale_m: 0.001,
        },
    )
    .unwrap_err();
    assert!(
        matches!(
            e,
            DepthError::PayloadLength {
                got: 11,
                want: 12,
                ..
            }
        ),
        "{e}"
    );
    let d = [0f32; 13];
    assert!(DepthView::new(4, 3, k(), DepthPixels::F32(&d)).is_err());
}

#[test]
fn zero_sizes_bad_focal_lengths_and_bad_scales_are_refused() {
    let d = [0u16; 12];
    let px = DepthPixels::U16 {
        data: &d,
        scale_m: 0.001,
    };
    assert!(DepthView::new(0, 3, k(), px).is_err());
    for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        let mut i = k();
        i.fx = bad;
        assert!(DepthView::new(4, 3, i, px).is_err());
    }
    let mut i = k();
    i.cy = f64::NAN;
    assert!(DepthView::new(4, 3, i, px).is_err());
    for scale in [0.0, -0.001, f32::NAN, 2.0] {
        let px = DepthPixels::U16 {
            data: &d,
            scale_m: scale,
        };
        assert!(DepthView::new(4, 3, k(), px).is_err());
    }
}

#[test]
fn a_wire_header_is_read_with_its_scale_and_intrinsics() {
    let header = DepthFrameHeader {
        width: 4,
        height: 3,
        depth_scale_m: 0.001,
        intrinsics: k(),
        ..DepthFrameHeader::default()
    };
    let d = [500u16; 12];
    let v = DepthView::from_wire(&header, &d).unwrap();
    assert_eq!(v.intrinsics(), k());
    let bad = DepthFrameHeader {
        depth_scale_m: f64::NAN,
        ..header
    };
    assert!(DepthView::from_wire(&bad, &d).is_err());
    let big = DepthFrameHeader {
        width: u32::MAX,
        height: u32::MAX,
        ..header
    };
    assert!(DepthView::from_wire(&big, &d).is_err());
}

use super::*;
use ndarray::Array3;

/// A person standing upright facing +z, feet on y = `lift`, swaying a little.
fn standing(lift: f32, frames: usize) -> Motion {
    let pose = crate::motion::skeleton::standing_pose();
    let mut positions = Array3::zeros((frames, NUM_JOINTS, 3));
    for f in 0..frames {
        let sway = 0.05 * (f as f32 * 0.3).sin();
        for (j, p) in pose.iter().enumerate() {
            positions[[f, j, 0]] = p[0] + sway;
            positions[[f, j, 1]] = p[1] + lift;
            positions[[f, j, 2]] = p[2];
        }
    }
    Motion {
        fps: 25.0,
        positions,
    }
}

fn rgb_of(motion: &Motion) -> Vec<u8> {
    let caption = Caption {
        model: "test".into(),
        seed: 1,
        song: Some("a song".into()),
        style: None,
    };
    let musicality = Musicality::of(motion, &[0.5, 1.0, 1.5]);
    let sheet = Sheet {
        motion,
        beat_times: &[0.5, 1.0, 1.5],
        key_pose_times: &[1.2],
        song_duration_s: motion.duration_s(),
        caption: &caption,
        musicality: &musicality,
    };
    render_rgb(&sheet).expect("draws")
}

fn pixel(rgb: &[u8], x: u32, y: u32) -> RGBColor {
    let i = ((y * WIDTH + x) * 3) as usize;
    RGBColor(rgb[i], rgb[i + 1], rgb[i + 2])
}

/// In the first figure of the front row: (the floor line's row, the lowest row a leg reaches).
fn floor_and_feet(rgb: &[u8]) -> (u32, u32) {
    let rows = TITLE_H..TITLE_H + ROW_H;
    let cols = ROW_LEFT as u32 + 2..ROW_LEFT as u32 + 140;
    let count = |y: u32, c: RGBColor| cols.clone().filter(|&x| pixel(rgb, x, y) == c).count();
    let floor = rows.clone().max_by_key(|&y| count(y, FLOOR)).expect("rows");
    assert!(count(floor, FLOOR) > 100, "a floor line crosses the cell");
    let feet = rows
        .filter(|&y| count(y, RIGHT) + count(y, LEFT) > 0)
        .max()
        .expect("legs are drawn");
    (floor, feet)
}

#[test]
fn the_floor_line_shows_a_floating_or_sinking_dancer() {
    let (floor, feet) = floor_and_feet(&rgb_of(&standing(0.0, 50)));
    assert!(
        feet.abs_diff(floor) <= 4,
        "grounded: feet at row {feet}, floor at {floor}"
    );
    let (floor, feet) = floor_and_feet(&rgb_of(&standing(0.5, 50)));
    assert!(
        floor > feet + 30,
        "floating 0.5 m: feet at row {feet} well above the floor at {floor}"
    );
    let (floor, feet) = floor_and_feet(&rgb_of(&standing(-0.4, 50)));
    assert!(
        feet > floor + 25,
        "sunk 0.4 m: feet at row {feet} well below the floor at {floor}"
    );
}

#[test]
fn the_png_decodes_to_the_picture() {
    let motion = standing(0.0, 30);
    let caption = Caption {
        model: "test".into(),
        seed: 3,
        song: None,
        style: None,
    };
    let musicality = Musicality::of(&motion, &[]);
    let sheet = Sheet {
        motion: &motion,
        beat_times: &[],
        key_pose_times: &[],
        song_duration_s: 1.2,
        caption: &caption,
        musicality: &musicality,
    };
    let bytes = render_png(&sheet).expect("png");
    let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
    let mut reader = decoder.read_info().expect("header");
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader.next_frame(&mut buf).expect("frame");
    assert_eq!((info.width, info.height), (WIDTH, HEIGHT));
    assert_eq!(
        &buf[..info.buffer_size()],
        render_rgb(&sheet).expect("rgb").as_slice()
    );
}

#[test]
fn bad_motions_are_refused_not_drawn() {
    let caption = Caption {
        model: "test".into(),
        seed: 0,
        song: None,
        style: None,
    };
    let empty = Motion {
        fps: 25.0,
        positions: Array3::zeros((0, NUM_JOINTS, 3)),
    };
    let musicality = Musicality::of(&empty, &[]);
    let sheet = |m| Sheet {
        motion: m,
        beat_times: &[],
        key_pose_times: &[],
        song_duration_s: 1.0,
        caption: &caption,
        musicality: &musicality,
    };
    assert!(matches!(
        render_rgb(&sheet(&empty)),
        Err(PreviewError::Empty)
    ));
    let few = Motion {
        fps: 25.0,
        positions: Array3::zeros((5, 3, 3)),
    };
    assert!(matches!(
        render_rgb(&sheet(&few)),
        Err(PreviewError::Joints(3))
    ));
}

//! Reading BVH: the hierarchy, then the frames, each bounded by the bytes sent (the joints are
//! capped, and `Frames:` × the channels must fit in the text that follows before a frame is
//! read), every number finite.
use nalgebra::{UnitQuaternion, Vector3};
use ndarray::Array3;

use crate::motion::rig::{Rig, RigMotion};
use crate::motion::skeleton::JOINT_NAMES;
use crate::motion::{Motion, MotionError, NUM_JOINTS};

/// One channel of a BVH joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Channel {
    Xposition,
    Yposition,
    Zposition,
    Xrotation,
    Yrotation,
    Zrotation,
}

/// A parsed BVH file.
#[derive(Clone, Debug)]
pub struct Bvh {
    pub names: Vec<String>,
    pub parents: Vec<Option<usize>>,
    pub offsets: Vec<Vector3<f64>>,
    pub channels: Vec<Vec<Channel>>,
    pub frame_time: f64,
    /// The channel values, frame after frame (`[T × width]`, in the file's joint order): one flat
    /// vector, so a frame costs its numbers and nothing more, however many frames there are.
    values: Vec<f64>,
    /// Channels per frame.
    width: usize,
    /// Frames in the file.
    num_frames: usize,
}

/// Largest BVH we parse (bytes): an hour at 60 fps of a 100-joint skeleton fits well within.
pub const MAX_BVH_BYTES: usize = 256 * 1024 * 1024;
/// Most joints a BVH may have: a Mixamo rig with fingers has 65, a VRoid avatar with hair and
/// skirt bones a few hundred. Each joint costs memory on every frame a tool reads.
pub const MAX_BVH_JOINTS: usize = 1024;

/// The fewest bytes one channel value takes in the text: a digit and a separator.
const MIN_BYTES_PER_VALUE: usize = 2;

impl Bvh {
    /// Parses BVH text: the hierarchy and every frame.
    ///
    /// What is allocated follows from the bytes sent, never from a number the file claims: the
    /// joints are capped ([`MAX_BVH_JOINTS`]), and `Frames:` × the channels per frame must fit in
    /// the text that follows (two bytes a value at least) before a frame is read, so a 1 KB file
    /// claiming ten billion frames is refused at once. Every number must be finite.
    pub fn parse(text: &str) -> Result<Bvh, MotionError> {
        let (mut bvh, mut tokens) = Self::parse_head(text)?;
        let n_frames = Self::parse_motion_header(&mut bvh, &mut tokens)?;
        let values = n_frames * bvh.width;
        bvh.values.reserve_exact(values);
        for _ in 0..values {
            let v: f64 = tokens.parse_num()?;
            if !v.is_finite() {
                return Err(tokens.not_finite("a channel value"));
            }
            bvh.values.push(v);
        }
        bvh.num_frames = n_frames;
        Ok(bvh)
    }

    /// Parses the hierarchy (a rig's rest pose) and, when the file goes on, checks its `MOTION`
    /// header as [`Bvh::parse`] does, without reading the frames: no frames are kept.
    pub fn parse_rest_pose(text: &str) -> Result<Bvh, MotionError> {
        let (mut bvh, mut tokens) = Self::parse_head(text)?;
        if tokens.peek_token().is_some() {
            Self::parse_motion_header(&mut bvh, &mut tokens)?;
        }
        Ok(bvh)
    }

    /// Reads `MOTION`, `Frames:` and `Frame Time:`; the number of frames, once it is known that
    /// the text that follows can hold them (so it is safe to allocate for).
    fn parse_motion_header(bvh: &mut Bvh, tokens: &mut Tokens<'_>) -> Result<usize, MotionError> {
        tokens.expect("MOTION")?;
        tokens.expect("Frames:")?;
        let n_frames: usize = tokens.parse_num()?;
        tokens.expect("Frame")?;
        tokens.expect("Time:")?;
        bvh.frame_time = tokens.parse_num()?;
        if !(bvh.frame_time > 0.0 && bvh.frame_time.is_finite()) {
            return Err(tokens.error(format!("invalid frame time {}", bvh.frame_time)));
        }
        let width = bvh.width;
        if width == 0 && n_frames > 0 {
            return Err(tokens.error(format!(
                "the hierarchy has no CHANNELS, so its {n_frames} frames carry no motion"
            )));
        }
        let values = n_frames.saturating_mul(width.max(1));
        let remaining = tokens.remaining_bytes();
        if values.saturating_mul(MIN_BYTES_PER_VALUE) > remaining + 1 {
            return Err(tokens.error(format!(
                "{n_frames} frames of {width} channels cannot fit in the {remaining} bytes that follow"
            )));
        }
        Ok(n_frames)
    }

    fn parse_head(text: &str) -> Result<(Bvh, Tokens<'_>), MotionError> {
        if text.len() > MAX_BVH_BYTES {
            return Err(MotionError::Bvh {
                line: 0,
                reason: format!("file larger than {MAX_BVH_BYTES} bytes"),
            });
        }
        let mut tokens = Tokens::new(text);
        tokens.expect("HIERARCHY")?;
        let mut bvh = Bvh {
            names: Vec::new(),
            parents: Vec::new(),
            offsets: Vec::new(),
            channels: Vec::new(),
            frame_time: 0.0,
            values: Vec::new(),
            width: 0,
            num_frames: 0,
        };
        let kw = tokens.next_token()?;
        if kw != "ROOT" {
            return Err(tokens.error(format!("expected ROOT, found {kw:?}")));
        }
        parse_joint(&mut tokens, &mut bvh, None, 0)?;
        bvh.width = bvh.channels.iter().map(Vec::len).sum();
        Ok((bvh, tokens))
    }

    /// Frames in the file.
    pub fn num_frames(&self) -> usize {
        self.num_frames
    }

    /// The channel values of frame `t`, in the file's joint order.
    pub fn frame(&self, t: usize) -> &[f64] {
        &self.values[t * self.width..(t + 1) * self.width]
    }

    /// Frames per second (1 / frame time).
    pub fn fps(&self) -> f64 {
        1.0 / self.frame_time
    }

    /// Local rotation and translation (offset plus any position channels) of each joint at frame `t`.
    pub fn local_pose(&self, t: usize) -> (Vec<Vector3<f64>>, Vec<UnitQuaternion<f64>>) {
        let mut trans = self.offsets.clone();
        let mut rots = vec![UnitQuaternion::identity(); self.names.len()];
        let row = self.frame(t);
        let mut k = 0;
        for (j, chans) in self.channels.iter().enumerate() {
            let mut q = UnitQuaternion::identity();
            for ch in chans {
                let v = row[k];
                k += 1;
                match ch {
                    Channel::Xposition => trans[j].x = self.offsets[j].x + v,
                    Channel::Yposition => trans[j].y = self.offsets[j].y + v,
                    Channel::Zposition => trans[j].z = self.offsets[j].z + v,
                    Channel::Xrotation => {
                        q *= UnitQuaternion::from_axis_angle(&Vector3::x_axis(), v.to_radians())
                    }
                    Channel::Yrotation => {
                        q *= UnitQuaternion::from_axis_angle(&Vector3::y_axis(), v.to_radians())
                    }
                    Channel::Zrotation => {
                        q *= UnitQuaternion::from_axis_angle(&Vector3::z_axis(), v.to_radians())
                    }
                }
            }
            rots[j] = q;
        }
        (trans, rots)
    }

    /// World positions of every joint at frame `t` (forward kinematics).
    pub fn world_frame(&self, t: usize) -> Vec<Vector3<f64>> {
        let (trans, rots) = self.local_pose(t);
        let n = self.names.len();
        let mut pos = vec![Vector3::zeros(); n];
        let mut world = vec![UnitQuaternion::identity(); n];
        // Joints are stored parent first, as the file nests them.
        for j in 0..n {
            match self.parents[j] {
                None => {
                    pos[j] = trans[j];
                    world[j] = rots[j];
                }
                Some(p) => {
                    pos[j] = pos[p] + world[p] * trans[j];
                    world[j] = world[p] * rots[j];
                }
            }
        }
        pos
    }

    /// World positions of every joint, `[T, J, 3]` (forward kinematics).
    pub fn world_positions(&self) -> Array3<f64> {
        let n = self.names.len();
        let mut out = Array3::zeros((self.num_frames, n, 3));
        for t in 0..self.num_frames {
            for (j, p) in self.world_frame(t).iter().enumerate() {
                for c in 0..3 {
                    out[[t, j, c]] = p[c];
                }
            }
        }
        out
    }

    /// The file's index of each of the 23 dataset joints, for a BVH that names them as we do.
    pub fn dataset_joints(&self) -> Result<Vec<usize>, MotionError> {
        JOINT_NAMES
            .iter()
            .map(|name| {
                self.names
                    .iter()
                    .position(|n| n == name)
                    .ok_or_else(|| MotionError::Invalid(format!("BVH has no joint named {name:?}")))
            })
            .collect()
    }

    /// The motion of the 23 dataset joints, for a BVH that names them as we do (metres, y up).
    pub fn to_motion(&self) -> Result<Motion, MotionError> {
        let idx = self.dataset_joints()?;
        let mut positions = Array3::zeros((self.num_frames, NUM_JOINTS, 3));
        for t in 0..self.num_frames {
            let world = self.world_frame(t);
            for (j, &k) in idx.iter().enumerate() {
                for c in 0..3 {
                    positions[[t, j, c]] = world[k][c] as f32;
                }
            }
        }
        Ok(Motion {
            fps: self.fps(),
            positions,
        })
    }

    /// The file as a rig motion, when it has one 6-channel root and 3 rotation channels elsewhere.
    pub fn to_rig_motion(&self) -> Result<RigMotion, MotionError> {
        let rig = Rig {
            names: self.names.clone(),
            parents: self.parents.clone(),
            offsets: self.offsets.clone(),
        };
        let mut root_translation = Vec::with_capacity(self.num_frames);
        let mut rotations = Vec::with_capacity(self.num_frames);
        for t in 0..self.num_frames {
            let (trans, rots) = self.local_pose(t);
            let joints = trans.iter().zip(&self.offsets).zip(&self.names);
            for ((at, offset), name) in joints.skip(1) {
                if (at - offset).norm() > 0.0 {
                    return Err(MotionError::Invalid(format!(
                        "joint {name} has position channels; only the root may"
                    )));
                }
            }
            let root = self.parents.iter().position(Option::is_none).unwrap_or(0);
            root_translation.push(trans[root] - rig.offsets[root]);
            rotations.push(rots);
        }
        Ok(RigMotion {
            rig,
            fps: self.fps(),
            root_translation,
            rotations,
        })
    }
}

fn parse_joint(
    tokens: &mut Tokens<'_>,
    bvh: &mut Bvh,
    parent: Option<usize>,
    depth: usize,
) -> Result<(), MotionError> {
    // Deeply nested input would only exhaust the stack.
    const MAX_DEPTH: usize = 256;
    if depth > MAX_DEPTH {
        return Err(tokens.error("hierarchy nested too deeply".into()));
    }
    if bvh.names.len() >= MAX_BVH_JOINTS {
        return Err(tokens.error(format!("more than {MAX_BVH_JOINTS} joints")));
    }
    let name = tokens.next_token()?.to_string();
    let j = bvh.names.len();
    bvh.names.push(name);
    bvh.parents.push(parent);
    bvh.offsets.push(Vector3::zeros());
    bvh.channels.push(Vec::new());
    tokens.expect("{")?;
    loop {
        let tok = tokens.next_token()?;
        match tok {
            "OFFSET" => {
                let x = tokens.parse_num()?;
                let y = tokens.parse_num()?;
                let z = tokens.parse_num()?;
                let offset = Vector3::new(x, y, z);
                if !offset.iter().all(|v: &f64| v.is_finite()) {
                    return Err(
                        tokens.not_finite(&format!("the OFFSET of joint {:?}", bvh.names[j]))
                    );
                }
                bvh.offsets[j] = offset;
            }
            "CHANNELS" => {
                let n: usize = tokens.parse_num()?;
                if n > 6 {
                    return Err(tokens.error(format!("{n} channels on one joint")));
                }
                for _ in 0..n {
                    let c = match tokens.next_token()? {
                        "Xposition" => Channel::Xposition,
                        "Yposition" => Channel::Yposition,
                        "Zposition" => Channel::Zposition,
                        "Xrotation" => Channel::Xrotation,
                        "Yrotation" => Channel::Yrotation,
                        "Zrotation" => Channel::Zrotation,
                        other => return Err(tokens.error(format!("unknown channel {other:?}"))),
                    };
                    bvh.channels[j].push(c);
                }
            }
            "JOINT" => parse_joint(tokens, bvh, Some(j), depth + 1)?,
            "End" => {
                tokens.expect("Site")?;
                tokens.expect("{")?;
                tokens.expect("OFFSET")?;
                for _ in 0..3 {
                    let v: f64 = tokens.parse_num()?;
                    if !v.is_finite() {
                        return Err(tokens.not_finite("an End Site OFFSET"));
                    }
                }
                tokens.expect("}")?;
            }
            "}" => return Ok(()),
            other => return Err(tokens.error(format!("unexpected {other:?}"))),
        }
    }
}

struct Tokens<'a> {
    iter: std::iter::Peekable<std::str::Lines<'a>>,
    current: std::str::SplitWhitespace<'a>,
    line: usize,
    /// The whole text, to tell how much of it is left.
    text: &'a str,
}

impl<'a> Tokens<'a> {
    fn new(text: &'a str) -> Self {
        Tokens {
            iter: text.lines().peekable(),
            current: "".split_whitespace(),
            line: 0,
            text,
        }
    }

    /// Bytes of the text not yet read (from the start of the next line; the current line's
    /// rest counts as read, which only makes the bound on frames tighter by a line).
    fn remaining_bytes(&mut self) -> usize {
        let rest = self.current.clone().map(str::len).sum::<usize>();
        let next = self
            .iter
            .peek()
            .map(|l| l.as_ptr() as usize - self.text.as_ptr() as usize);
        rest + next.map_or(0, |start| self.text.len().saturating_sub(start))
    }

    fn not_finite(&self, what: &str) -> MotionError {
        MotionError::NotFinite {
            line: self.line,
            what: what.to_string(),
        }
    }

    fn next_token(&mut self) -> Result<&'a str, MotionError> {
        loop {
            if let Some(t) = self.current.next() {
                return Ok(t);
            }
            match self.iter.next() {
                Some(l) => {
                    self.line += 1;
                    self.current = l.split_whitespace();
                }
                None => return Err(self.error("unexpected end of file".into())),
            }
        }
    }

    /// The next token, left unread; none at the end of the text.
    fn peek_token(&mut self) -> Option<&'a str> {
        if let Some(t) = self.current.clone().next() {
            return Some(t);
        }
        while let Some(line) = self.iter.peek() {
            if let Some(t) = line.split_whitespace().next() {
                return Some(t);
            }
            self.iter.next();
            self.line += 1;
        }
        None
    }

    fn expect(&mut self, want: &str) -> Result<(), MotionError> {
        let got = self.next_token()?;
        if got == want {
            Ok(())
        } else {
            Err(self.error(format!("expected {want:?}, found {got:?}")))
        }
    }

    fn parse_num<T: std::str::FromStr>(&mut self) -> Result<T, MotionError> {
        let tok = self.next_token()?;
        tok.parse()
            .map_err(|_| self.error(format!("expected a number, found {tok:?}")))
    }

    fn error(&self, reason: String) -> MotionError {
        MotionError::Bvh {
            line: self.line,
            reason,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_a_small_file_and_rejects_broken_ones() {
        let text = "HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n JOINT b\n {\n  OFFSET 0 1 0\n  CHANNELS 3 Zrotation Yrotation Xrotation\n  End Site\n  {\n   OFFSET 0 1 0\n  }\n }\n}\nMOTION\nFrames: 2\nFrame Time: 0.04\n1 2 3 0 0 0 0 0 0\n1 2 3 90 0 0 0 0 0\n";
        let b = Bvh::parse(text).expect("parse");
        assert_eq!(b.names, vec!["a", "b"]);
        assert_eq!(b.num_frames(), 2);
        let w = b.world_positions();
        assert!((w[[0, 1, 1]] - 3.0).abs() < 1e-9);
        // Rotating the root 90° about z takes the child's +y offset to −x.
        assert!((w[[1, 1, 0]] - 0.0).abs() < 1e-9, "{}", w[[1, 1, 0]]);
        assert!(Bvh::parse(&text.replace("Frames: 2", "Frames: 3")).is_err());
        assert!(Bvh::parse(&text.replace("CHANNELS 3", "CHANNELS 4")).is_err());
        assert!(Bvh::parse(&text.replace("90", "nan")).is_err());
        assert!(Bvh::parse("HIERARCHY\nROOT").is_err());
    }

    const TWO_JOINTS: &str = "HIERARCHY\nROOT a\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n JOINT b\n {\n  OFFSET 0 1 0\n  CHANNELS 3 Zrotation Yrotation Xrotation\n  End Site\n  {\n   OFFSET 0 1 0\n  }\n }\n}\nMOTION\nFrames: 1\nFrame Time: 0.04\n1 2 3 0 0 0 0 0 0\n";

    /// A frame count the text cannot hold is refused before anything is allocated for it,
    /// whatever the width of a frame (none: every CHANNELS clause removed).
    #[test]
    fn claimed_frames_are_held_to_the_bytes_that_follow() {
        let no_channels = TWO_JOINTS
            .lines()
            .filter(|l| !l.contains("CHANNELS"))
            .collect::<Vec<_>>()
            .join("\n");
        for frames in ["10000000000", "1000000000000000000", "18446744073709551615"] {
            for text in [&no_channels, TWO_JOINTS] {
                let claimed = text.replace("Frames: 1", &format!("Frames: {frames}"));
                let err = Bvh::parse(&claimed).expect_err("refused");
                assert_eq!(err.code(), "invalid-bvh", "{err}");
            }
        }
        // Without channels and without frames, it is a hierarchy (a rig's rest pose).
        let rest = no_channels.replace("Frames: 1", "Frames: 0");
        let rest = rest.replace("1 2 3 0 0 0 0 0 0", "");
        assert_eq!(Bvh::parse(&rest).expect("a rest pose").num_frames(), 0);
        // A rest pose is read without its frames, but its claim is checked all the same.
        let rest = Bvh::parse_rest_pose(TWO_JOINTS).expect("rest pose");
        assert_eq!((rest.names.len(), rest.num_frames()), (2, 0));
        let hierarchy = &TWO_JOINTS[..TWO_JOINTS.find("MOTION").expect("motion")];
        assert!(Bvh::parse_rest_pose(hierarchy).is_ok());
        assert!(
            Bvh::parse_rest_pose(&TWO_JOINTS.replace("Frames: 1", "Frames: 99999999")).is_err()
        );
    }

    #[test]
    fn numbers_must_be_finite_and_joints_few() {
        for (from, to) in [
            ("OFFSET 0 1 0\n  CHANNELS", "OFFSET NaN 1 0\n  CHANNELS"),
            ("OFFSET 0 1 0\n  }", "OFFSET 0 inf 0\n  }"),
            ("Frame Time: 0.04\n1 2 3", "Frame Time: 0.04\n1 -inf 3"),
        ] {
            assert!(TWO_JOINTS.contains(from), "{from}");
            let err = Bvh::parse(&TWO_JOINTS.replace(from, to)).expect_err("refused");
            assert_eq!(err.code(), "motion-not-finite", "{to}: {err}");
        }
        let mut many = String::from("HIERARCHY\nROOT j0\n{\n OFFSET 0 0 0\n");
        for j in 1..=MAX_BVH_JOINTS {
            many.push_str(&format!(" JOINT j{j}\n {{\n  OFFSET 0 0 0\n }}\n"));
        }
        many.push_str("}\nMOTION\nFrames: 0\nFrame Time: 0.04\n");
        let err = Bvh::parse(&many).expect_err("refused");
        assert!(err.to_string().contains("more than 1024 joints"), "{err}");
    }
}

//! DanceNet: Zhuang, Wang, Chai, Wang, Shao, Xia, "Music2Dance: DanceNet for Music-driven Dance Generation" (2020).
pub mod style;

//! TSMT's three diversity measures (Li et al., "Learning to Generate Diverse Dance Motions with
//! Transformer", 2020, §5): how different the dances are from each other (A-seq-D), within
//! themselves (I-seq-D), and for one song under different seeds (S-music-D).
//!
//! The paper measures distances between features of a learned motion encoder; we have none
//! trained on this data, so every distance here is between z-normalised AIST++ kinetic features
//! of 5-s windows ([`super::reference`]), the features behind FID_k. Each dance is a list of
//! window feature vectors; a dance's own feature is the mean of its windows.
//! - **A-seq-D**: the mean pairwise Euclidean distance between the dances' mean features, over
//!   every dance of a set (whatever its song).
//! - **I-seq-D**: for each dance, the mean pairwise distance between its own windows; averaged
//!   over dances. A dance that repeats one move or freezes scores near 0.
//! - **S-music-D**: for each song with at least two dances, the mean pairwise distance between
//!   those dances' mean features; averaged over songs.
use super::fid::mean_pairwise_distance;

/// The three measures of a set of dances (`None` where too few dances or windows).
#[derive(
    Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, utoipa::ToSchema,
)]
pub struct Diversity {
    pub a_seq_d: Option<f64>,
    pub i_seq_d: Option<f64>,
    pub s_music_d: Option<f64>,
}

/// The mean of a dance's window features (`None` without windows).
pub fn mean_feature(windows: &[Vec<f64>]) -> Option<Vec<f64>> {
    let first = windows.first()?;
    let mut m = vec![0.0; first.len()];
    for w in windows {
        for (a, b) in m.iter_mut().zip(w) {
            *a += b;
        }
    }
    let n = windows.len() as f64;
    Some(m.into_iter().map(|v| v / n).collect())
}

/// A-seq-D over `dances` (each a list of window features).
pub fn a_seq_d(dances: &[&[Vec<f64>]]) -> Option<f64> {
    let means: Vec<Vec<f64>> = dances.iter().filter_map(|d| mean_feature(d)).collect();
    (means.len() >= 2).then(|| mean_pairwise_distance(&means))
}

/// I-seq-D over `dances`: the mean over dances with at least two windows of their windows'
/// mean pairwise distance.
pub fn i_seq_d(dances: &[&[Vec<f64>]]) -> Option<f64> {
    let per: Vec<f64> = dances
        .iter()
        .filter(|d| d.len() >= 2)
        .map(|d| mean_pairwise_distance(d))
        .collect();
    (!per.is_empty()).then(|| per.iter().sum::<f64>() / per.len() as f64)
}

/// S-music-D over songs, each a list of dances of that song.
pub fn s_music_d(per_song: &[Vec<&[Vec<f64>]>]) -> Option<f64> {
    let per: Vec<f64> = per_song.iter().filter_map(|song| a_seq_d(song)).collect();
    (!per.is_empty()).then(|| per.iter().sum::<f64>() / per.len() as f64)
}

/// All three for dances grouped by song.
pub fn diversity(per_song: &[Vec<&[Vec<f64>]>]) -> Diversity {
    let all: Vec<&[Vec<f64>]> = per_song.iter().flatten().copied().collect();
    Diversity {
        a_seq_d: a_seq_d(&all),
        i_seq_d: i_seq_d(&all),
        s_music_d: s_music_d(per_song),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `n` windows of one 2-d feature, each `step` further along x from `start`.
    fn dance(start: f64, step: f64, n: usize) -> Vec<Vec<f64>> {
        (0..n).map(|i| vec![start + step * i as f64, 0.0]).collect()
    }

    #[test]
    fn a_frozen_dance_has_no_inner_diversity() {
        let frozen = dance(1.0, 0.0, 5);
        let moving = dance(0.0, 1.0, 3); // windows at 0, 1, 2: pairwise 1, 2, 1
        assert_eq!(i_seq_d(&[&frozen]), Some(0.0));
        let d = i_seq_d(&[&moving]).unwrap();
        assert!((d - 4.0 / 3.0).abs() < 1e-12, "{d}");
        // Averaged over dances.
        let both = i_seq_d(&[&frozen, &moving]).unwrap();
        assert!((both - 2.0 / 3.0).abs() < 1e-12, "{both}");
    }

    #[test]
    fn across_dances_uses_each_dance_mean() {
        // Means at x = 1 and x = 4: distance 3, whatever the spread inside.
        let a = dance(0.0, 1.0, 3);
        let b = dance(4.0, 0.0, 2);
        assert!((a_seq_d(&[&a, &b]).unwrap() - 3.0).abs() < 1e-12);
        assert_eq!(a_seq_d(&[&a]), None);
    }

    #[test]
    fn same_music_only_compares_dances_of_one_song() {
        // Song 1: two identical dances (0 apart); song 2: means 2 apart. Across songs they are far.
        let s1a = dance(0.0, 0.0, 2);
        let s1b = dance(0.0, 0.0, 2);
        let s2a = dance(10.0, 0.0, 2);
        let s2b = dance(12.0, 0.0, 2);
        let songs = vec![
            vec![s1a.as_slice(), s1b.as_slice()],
            vec![s2a.as_slice(), s2b.as_slice()],
        ];
        let d = diversity(&songs);
        assert!((d.s_music_d.unwrap() - 1.0).abs() < 1e-12, "{:?}", d);
        assert!(d.a_seq_d.unwrap() > 5.0, "{:?}", d);
        assert_eq!(d.i_seq_d, Some(0.0));
        // A song with one dance gives no S-music-D.
        assert_eq!(s_music_d(&[vec![s1a.as_slice()]]), None);
    }
}

//! Kept histories ([`KeptHistory`]): the file in `/dev/shm` where a primitive
//! trajectory's writer keeps what it acknowledged, which every process of the domain
//! may write, and which a reader reads when the writer is gone and a restarted writer
//! continues. A damaged or hostile file must be refused or read in part, never read
//! out of bounds.
//!
//! An input is a whole file, written where the trajectory's kept history lives: its
//! header, its holders' page (which every reading process writes), its slots and its
//! area. The seeds are files a writer wrote: robot states under each retention,
//! images, a reset, a wrapped area, and one whose holders' page names a reader that
//! died holding an entry. Readers read entries in place (held, then checked), so this
//! is also the in-place reader's fuzzing. Promises beyond "no panic": a reader never
//! returns more entries than slots, nor one at an index the file has not reached, and
//! every entry it returns reads whole through the in-place accessors; a writer always
//! continues or replaces the file and keeps the next structure, which a reader then
//! reads back; every seed reads whole.

use esgm_core::Entity;
use esgm_core::library::{Image, RobotState};
use esgm_shm::unstable::{KeptHistory, Retention};

use crate::mutate::mutate;
use crate::rng::Rng;
use crate::target::{Broken, Target};

/// The type id the seeds are kept under.
const TYPE_ID: u64 = 0x5eed;

/// Makes the `i`th structure of a seed.
type Make = fn(i64) -> esgm_core::EntityStructure;

/// The kept-history target.
#[derive(Debug)]
pub struct Kept {
    seeds: Vec<Vec<u8>>,
    /// The domain (a generation's) each case's file is written in.
    domain: String,
}

impl Drop for Kept {
    fn drop(&mut self) {
        KeptHistory::remove_domain(&self.domain);
    }
}

fn robot(i: i64) -> esgm_core::EntityStructure {
    RobotState { x: i as f64, y: 1.0, dir: 2.0 }.to_structure("robot", i, i)
}

fn image(i: i64) -> esgm_core::EntityStructure {
    let pixels: Vec<u8> = (0..8 * 4 * 3).map(|p| (p + i) as u8).collect();
    Image { width: 8, height: 4, format: Image::FORMAT_RGB8, image_data: pixels.into() }
        .to_structure("camera", i, i)
}

impl Kept {
    /// Writes the seeds with the writer's own code.
    pub fn new() -> Result<Self, Broken> {
        let domain = format!("fuzz-kept-{}.g0", std::process::id());
        let broken = |e: &dyn std::fmt::Display| Broken::new("a seed kept history is written", e);
        let mut seeds = Vec::new();
        let cases: [(&str, Retention, Make, i64); 4] = [
            ("all", Retention::All, robot, 12),
            ("count", Retention::Count(3), robot, 40),
            ("window", Retention::Window(5), image, 20),
            ("reset", Retention::Count(8), robot, 6),
        ];
        for (name, retention, make, n) in cases {
            let mut w = KeptHistory::open_or_create(&domain, name, TYPE_ID, retention)
                .map_err(|e| broken(&e))?;
            for i in 0..n {
                w.append(&make(i), 1_000 + i).map_err(|e| broken(&e))?;
            }
            if name == "reset" {
                w.reset();
                w.append(&robot(99), 9_999).map_err(|e| broken(&e))?;
            }
            seeds.push(std::fs::read(w.path()).map_err(|e| broken(&e))?);
            if name == "count" {
                // A reader that holds an entry, as its file is copied: the copy names a
                // holder whose lock nobody holds (a reader that died holding it).
                let reader = KeptHistory::open(&domain, name).map_err(|e| broken(&e))?;
                let held = reader.map(|r| r.entries());
                seeds.push(std::fs::read(w.path()).map_err(|e| broken(&e))?);
                drop(held);
            }
        }
        Ok(Self { seeds, domain })
    }

    /// Writes `input` as the case's file.
    fn place(&self, input: &[u8]) -> Result<(), Broken> {
        std::fs::write(KeptHistory::path_for(&self.domain, "case"), input)
            .map_err(|e| Broken::new("the case's file is written", e))
    }

    /// Reads the case's file; how many entries it read, if it opened.
    fn read(&self) -> Result<Option<usize>, Broken> {
        let Ok(Some(kept)) = KeptHistory::open(&self.domain, "case") else {
            return Ok(None);
        };
        let read = kept.entries();
        // Every entry returned reads whole in place (attributes, nested values).
        for e in &read.entries {
            std::hint::black_box(e.structure.to_structure());
        }
        let increasing = read.entries.windows(2).all(|w| w[0].index < w[1].index);
        if read.entries.len() as u64 > kept.capacity()
            || read.entries.iter().any(|e| e.index >= read.next)
            || !increasing
        {
            return Err(Broken::new(
                "a reader returns at most a file's slots, in order, below the next index",
                format!(
                    "{} entries of {} slots, next {}, indices {:?}",
                    read.entries.len(),
                    kept.capacity(),
                    read.next,
                    read.entries.iter().map(|e| e.index).take(8).collect::<Vec<_>>()
                ),
            ));
        }
        Ok(Some(read.entries.len()))
    }
}

impl Target for Kept {
    fn name(&self) -> &'static str {
        "kept"
    }

    fn about(&self) -> &'static str {
        "KeptHistory::open and entries (a reader), open_or_create and append (a writer \
         continuing), on damaged kept-history files"
    }

    fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }

    fn input(&self, rng: &mut Rng) -> Vec<u8> {
        let mut data = rng.pick(&self.seeds).clone();
        mutate(rng, &mut data, &self.seeds);
        data
    }

    fn run(&self, input: &[u8]) -> Result<(), Broken> {
        self.place(input)?;
        self.read()?;
        // A writer coming back to this file continues or replaces it, and keeps.
        let mut w = KeptHistory::open_or_create(&self.domain, "case", TYPE_ID, Retention::Count(4))
            .map_err(|e| Broken::new("a writer continues or replaces any file", e))?;
        let index = w
            .append(&robot(7), 7_000)
            .map_err(|e| Broken::new("a writer keeps the next structure in any file", e))?;
        drop(w);
        let Ok(Some(kept)) = KeptHistory::open(&self.domain, "case") else {
            return Err(Broken::new("a file a writer kept in opens", "refused"));
        };
        let read = kept.entries();
        match read.entries.last() {
            Some(e) if e.index == index && e.structure.valid_time() == 7 => Ok(()),
            other => Err(Broken::new(
                "the structure a writer just kept is read back last",
                format!("{:?}", other.map(|e| (e.index, e.structure.valid_time()))),
            )),
        }
    }

    fn accepts(&self, seed: &[u8]) -> Result<(), Broken> {
        self.place(seed)?;
        let Ok(Some(kept)) = KeptHistory::open(&self.domain, "case") else {
            return Err(Broken::new("a seed opens", "refused"));
        };
        let read = kept.entries();
        if read.skipped > 0 || read.entries.is_empty() {
            return Err(Broken::new(
                "a seed reads whole",
                format!("{} entries, {} skipped", read.entries.len(), read.skipped),
            ));
        }
        Ok(())
    }
}

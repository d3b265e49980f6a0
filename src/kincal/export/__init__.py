"""Everything kincal writes: corrected URDF, frames, reports, plots, all atomically."""

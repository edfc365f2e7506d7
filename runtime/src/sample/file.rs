//! Initial states read from files: extended XYZ and rovib's internal CSV.

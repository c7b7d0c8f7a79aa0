//! Fixed-width text tables of the reports, as the CLI prints them.

"""The bottom layer: the typed specs and errors (types), the run record's schema (record), the
environment and Mitsuba variant (env) and clock reads (timing). It imports no other part of dsm."""

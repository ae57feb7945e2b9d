"""The headline experiment's outputs: `write` builds summary.json and writes report.md and plots/;
`text` and `evidence` put the figures in words a reader can check; `goals` says which goal each
figure meets; `equal_time` sets the RL arms beside each other at equal wall-clock.

The pictures (`experiment.plots`), the formatting of figures (`experiment.formatting`) and the
reports that Dyna and the imagination measurement write themselves stay beside those measurements:
the headline's report reads the measurements, so they cannot read back from here."""

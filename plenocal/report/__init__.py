"""The report: one self-contained HTML page per dataset (:mod:`plenocal.report.html`),
its figures drawn without matplotlib (:mod:`plenocal.report.figures`), and where its
sources live and how their figures are laid out as in Table I and Figs. 7-9
(:mod:`plenocal.report.sources`); the evaluation files are read through
:mod:`plenocal.artifacts.results`."""

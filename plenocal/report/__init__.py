"""The report: one self-contained HTML page per dataset (:mod:`plenocal.report.html`),
its figures drawn without matplotlib (:mod:`plenocal.report.figures`), and the readers
of the evaluation files (:mod:`plenocal.report.sources`)."""

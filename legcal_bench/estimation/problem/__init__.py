"""The contact-constrained problem: residuals, terms, solver, frame selection and the framework's fit."""

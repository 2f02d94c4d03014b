"""Drug interaction domain: ANSM interaction rules, dose, renal, hepatic and pregnancy checks."""

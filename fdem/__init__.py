"""fdem package."""

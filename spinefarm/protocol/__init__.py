"""Contracts every spinefarm service shares. Imports only numpy and the standard library."""

"""Test and benchmark utilities: reference implementations flagsim is checked against."""

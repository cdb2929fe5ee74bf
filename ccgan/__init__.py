"""Conditional CycleGAN (CCGAN-GP) domain translation of soft-arm pressure programs."""

from ccgan.translator import Translator, load_translator

__all__ = ["Translator", "load_translator"]

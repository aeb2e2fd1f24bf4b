"""Strand physics: the horse's tail (many strands, and one strand driving a bone chain) and the rider's braid."""

from __future__ import annotations

"""Implicit blocks: fractured rock blocks replicated over a host field (implicit-blocks-2020)."""

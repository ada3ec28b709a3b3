"""Module state reached as plant.state.events."""

events = []

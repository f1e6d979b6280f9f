"""The vocabulary of object descriptions, and what the topology reads from a description.

A foundation model's scene comes with one short description per object ("white curtains on left window", "wooden
cabinet partially visible in the bottom left"). Its head, the words before the first preposition, names the object
itself; the rest names where it is. The wall-object and fragment rules of :mod:`phiscene.topology.attached` and the
floor prior of :mod:`phiscene.topology.floor` read descriptions with these helpers.
"""

from __future__ import annotations

import re

#: Words naming objects that are normally fixed to a wall or the ceiling.
WALL_WORDS = ("poster", "painting", "picture", "artwork", "art", "framed", "window", "curtain", "curtains",
              "blind", "blinds", "whiteboard", "blackboard", "chalkboard", "clock", "mirror", "fan", "chandelier",
              "sconce", "pendant", "canvas", "print", "photo", "photograph", "calendar", "board", "tapestry")
#: Words naming building fixtures: attached wherever they reach (:mod:`phiscene.topology.attached`).
FIXTURE_WORDS = ("window", "windows", "curtain", "curtains", "drape", "drapes", "blind", "blinds", "radiator",
                 "radiators")
#: Prepositions that end a description's head ("<head> on the <supporter>").
HEAD_END = ("on", "under", "in", "at", "by", "near", "beside", "above", "below", "next", "with", "over", "against",
            "behind", "between", "beneath", "underneath", "inside", "atop", "along", "across", "around")
#: Phrases saying an object is mounted (matched in the lower-case description).
MOUNT_PHRASES = ("on the wall", "on wall", "wall mounted", "wall-mounted", "mounted", "hanging", "hung",
                 "on the ceiling", "from the ceiling", "ceiling")
#: A description saying an object stands or leans against a wall ("mattress leaning against wall", "plank against
#: the back wall", "board leaning on the wall").
AGAINST_WALL = re.compile(r"\b(against|leaning on|leans on|propped on)\s+(the\s+|a\s+)?([a-z]+\s+)?wall\b")
#: Words saying an object is seen only in part (its lower part may be missing from the reconstruction).
PARTIAL_WORDS = ("partially", "partly", "partial", "occluded", "truncated", "cropped", "cut")

#: Head nouns of furniture that stands on the floor.
FURNITURE_WORDS = ("chair", "chairs", "armchair", "table", "tables", "desk", "sofa", "couch", "bed", "cabinet",
                   "dresser", "wardrobe", "bookshelf", "bookcase", "nightstand", "stool", "bench", "ottoman",
                   "sideboard", "cupboard", "drawers", "refrigerator", "fridge", "piano", "armoire", "credenza",
                   "shelf", "shelves", "shelving", "rack", "stand", "chest")
#: Head nouns of the room's own surfaces: a reconstruction that meshes its floor, walls or ceiling as objects
#: ("white wall", "wooden floor"; not "wall clock" or "floor lamp", whose head nouns are others).
STRUCTURE_WORDS = ("wall", "walls", "floor", "floors", "flooring", "ceiling", "ceilings", "ground", "layout")
#: Words that also end the head of a description read for :data:`STRUCTURE_WORDS` ("basket hanging from ceiling",
#: "back wall of the room").
STRUCTURE_HEAD_END = ("from", "of", "to", "for")
#: Words after the head noun that do not name another object ("wooden cabinet partially visible", "chair 87 cm").
TRAILING = ("partially", "partly", "visible", "occluded", "cut", "off", "cropped", "cm", "mm", "m", "x")


def has_word(description: str, words: tuple[str, ...]) -> bool:
    """Whether one of a description's lower-case words is in ``words``."""
    return bool(set(re.findall(r"[a-z]+", description.lower())) & set(words))


def names_wall_object(description: str) -> bool:
    """Whether a description names a wall or ceiling object (a word of :data:`WALL_WORDS`)."""
    return has_word(description, WALL_WORDS)


def says_mounted(description: str) -> bool:
    """Whether a description names a wall/ceiling object or says it is mounted (:data:`WALL_WORDS`, phrases)."""
    return names_wall_object(description) or any(p in description.lower() for p in MOUNT_PHRASES)


def head_words(description: str, end: tuple[str, ...] = ()) -> list[str]:
    """The lower-case words of a description's head: those before its first :data:`HEAD_END` preposition, or its
    first word of ``end`` ("white curtains on the left window" -> ["white", "curtains"])."""
    head = []
    for w in re.findall(r"[a-z]+", description.lower()):
        if w in HEAD_END or w in end:
            break
        head.append(w)
    return head


def names_fixture(description: str) -> bool:
    """Whether a description's head (:func:`head_words`) names a building fixture (:data:`FIXTURE_WORDS`)."""
    return bool(set(head_words(description)) & set(FIXTURE_WORDS))


def says_partial(description: str) -> bool:
    """Whether a description says the object is seen only in part (a word of :data:`PARTIAL_WORDS`)."""
    return has_word(description, PARTIAL_WORDS)


def head_noun(description: str, end: tuple[str, ...] = ()) -> str:
    """The last word of a description's head (:func:`head_words`, ending also at a word of ``end``), trailing
    qualifiers and units (:data:`TRAILING`) skipped: "white and gold table lamp on nightstand" -> "lamp",
    "wooden chair 87 cm" -> "chair", "wooden cabinet partially visible in the bottom left" -> "cabinet"."""
    head = head_words(description, end)
    while head and head[-1] in TRAILING:
        head.pop()
    return head[-1] if head else ""


def names_furniture(description: str) -> bool:
    """Whether a description's head noun (:func:`head_noun`) is floor furniture (:data:`FURNITURE_WORDS`) and it does
    not say the object is mounted (:func:`says_mounted`: a wall-mounted shelf)."""
    return head_noun(description) in FURNITURE_WORDS and not says_mounted(description)


def names_structure(description: str) -> bool:
    """Whether a description's head noun is one of the room's surfaces (:data:`STRUCTURE_WORDS`): "white wall",
    "wooden floor on the left", "back wall of the room" yes; "wall clock", "floor lamp", "ceiling fan", "basket
    hanging from ceiling" no. The head ends at a :data:`HEAD_END` preposition or one of :data:`STRUCTURE_HEAD_END`,
    so what the object hangs from or belongs to is not read as the object."""
    return head_noun(description, STRUCTURE_HEAD_END) in STRUCTURE_WORDS


def says_against_wall(description: str) -> bool:
    """Whether a description says the object stands or leans against a wall (:data:`AGAINST_WALL`)."""
    return AGAINST_WALL.search(description.lower().replace("_", " ")) is not None

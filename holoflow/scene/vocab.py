"""The words the procedural scene generator understands (documented in docs/panorama.md).

Colours are linear-light albedos. Each table maps a prompt word to what it changes; the generator
(holoflow.scene.generate) reads only these tables, so adding a word is a one-line change.
"""
from __future__ import annotations

COLORS = {
    "red": (0.50, 0.05, 0.04), "crimson": (0.42, 0.02, 0.05), "maroon": (0.22, 0.02, 0.02),
    "orange": (0.78, 0.28, 0.04), "yellow": (0.78, 0.62, 0.06), "gold": (0.66, 0.45, 0.10),
    "golden": (0.66, 0.45, 0.10), "green": (0.08, 0.32, 0.07), "emerald": (0.03, 0.35, 0.15),
    "olive": (0.20, 0.22, 0.05), "teal": (0.02, 0.25, 0.25), "turquoise": (0.08, 0.52, 0.46),
    "cyan": (0.05, 0.55, 0.65), "blue": (0.05, 0.13, 0.50), "navy": (0.01, 0.02, 0.15),
    "purple": (0.22, 0.05, 0.38), "violet": (0.30, 0.10, 0.55), "lavender": (0.52, 0.42, 0.70),
    "magenta": (0.60, 0.05, 0.45), "pink": (0.80, 0.35, 0.45), "white": (0.80, 0.80, 0.78),
    "ivory": (0.82, 0.78, 0.64), "cream": (0.76, 0.68, 0.48), "beige": (0.58, 0.48, 0.32),
    "tan": (0.48, 0.33, 0.18), "brown": (0.22, 0.10, 0.04), "black": (0.025, 0.025, 0.025),
    "grey": (0.28, 0.28, 0.28), "gray": (0.28, 0.28, 0.28), "silver": (0.55, 0.55, 0.58),
}
SHADES = {"dark": 0.4, "deep": 0.55, "light": 1.6, "pale": 1.8, "bright": 1.3}

# material word -> (kind, colour, second colour, pattern scale in metres)
MATERIALS = {
    "wood": ("wood", (0.33, 0.17, 0.07), (0.16, 0.07, 0.025), 0.14),
    "wooden": ("wood", (0.33, 0.17, 0.07), (0.16, 0.07, 0.025), 0.14),
    "oak": ("wood", (0.42, 0.25, 0.11), (0.24, 0.13, 0.05), 0.16),
    "pine": ("wood", (0.55, 0.38, 0.18), (0.36, 0.22, 0.09), 0.12),
    "walnut": ("wood", (0.16, 0.07, 0.03), (0.07, 0.03, 0.012), 0.14),
    "mahogany": ("wood", (0.22, 0.06, 0.03), (0.10, 0.025, 0.01), 0.14),
    "parquet": ("wood", (0.38, 0.2, 0.08), (0.2, 0.09, 0.03), 0.08),
    "timber": ("wood", (0.35, 0.2, 0.09), (0.18, 0.09, 0.03), 0.2),
    "brick": ("brick", (0.40, 0.11, 0.05), (0.50, 0.47, 0.42), 0.24),
    "bricks": ("brick", (0.40, 0.11, 0.05), (0.50, 0.47, 0.42), 0.24),
    "tile": ("tiles", (0.72, 0.72, 0.70), (0.30, 0.30, 0.28), 0.30),
    "tiles": ("tiles", (0.72, 0.72, 0.70), (0.30, 0.30, 0.28), 0.30),
    "tiled": ("tiles", (0.72, 0.72, 0.70), (0.30, 0.30, 0.28), 0.30),
    "ceramic": ("tiles", (0.72, 0.72, 0.70), (0.30, 0.30, 0.28), 0.15),
    "plaster": ("plaster", (0.70, 0.66, 0.58), (0.60, 0.56, 0.50), 1.0),
    "stucco": ("plaster", (0.72, 0.64, 0.50), (0.60, 0.52, 0.40), 0.5),
    "concrete": ("concrete", (0.38, 0.38, 0.36), (0.30, 0.30, 0.29), 1.0),
    "cement": ("concrete", (0.42, 0.41, 0.39), (0.32, 0.32, 0.30), 1.0),
    "marble": ("marble", (0.80, 0.78, 0.74), (0.22, 0.22, 0.24), 1.0),
    "stone": ("stone", (0.36, 0.33, 0.29), (0.22, 0.21, 0.19), 0.6),
    "cobblestone": ("stone", (0.30, 0.29, 0.27), (0.18, 0.17, 0.16), 0.3),
    "carpet": ("carpet", (0.35, 0.10, 0.08), (0.55, 0.45, 0.20), 0.5),
    "carpeted": ("carpet", (0.35, 0.10, 0.08), (0.55, 0.45, 0.20), 0.5),
    "velvet": ("fabric", (0.30, 0.03, 0.08), (0.2, 0.02, 0.05), 1.0),
    "fabric": ("fabric", (0.40, 0.38, 0.34), (0.3, 0.28, 0.25), 1.0),
    "linen": ("fabric", (0.70, 0.66, 0.58), (0.6, 0.56, 0.5), 1.0),
    "wool": ("fabric", (0.55, 0.50, 0.42), (0.45, 0.4, 0.33), 1.0),
    "leather": ("leather", (0.20, 0.08, 0.03), (0.10, 0.04, 0.015), 1.0),
    "metal": ("metal", (0.50, 0.50, 0.52), (0.3, 0.3, 0.32), 1.0),
    "steel": ("metal", (0.45, 0.46, 0.48), (0.3, 0.3, 0.32), 1.0),
    "iron": ("metal", (0.18, 0.18, 0.19), (0.1, 0.1, 0.1), 1.0),
    "chrome": ("metal", (0.65, 0.65, 0.68), (0.4, 0.4, 0.42), 1.0),
}

# nouns that take colour / material words; value = the part of the scene they colour
TARGETS = {
    "floor": "floor", "floors": "floor", "ground": "ground", "wall": "wall", "walls": "wall",
    "ceiling": "ceiling", "sofa": "sofa", "couch": "sofa", "bed": "bed", "table": "table", "desk": "table",
    "chair": "chair", "chairs": "chair", "armchair": "sofa", "shelf": "shelves", "shelves": "shelves",
    "bookshelf": "shelves", "bookshelves": "shelves", "bookcase": "shelves", "lamp": "lamp", "rug": "rug",
    "curtains": "rug", "cabinet": "cabinet", "cabinets": "cabinet", "counter": "cabinet",
    "wardrobe": "cabinet", "sky": "sky", "grass": "ground", "tree": "tree", "trees": "tree",
    "forest": "tree", "leaves": "tree", "rock": "rock", "rocks": "rock", "boulders": "rock",
    "water": "water", "lake": "water", "sea": "water", "ocean": "water", "river": "water", "pond": "water",
    "house": "building", "houses": "building", "building": "building", "buildings": "building",
    "cottage": "building", "tower": "building", "towers": "building", "skyscrapers": "building",
    "hill": "hill", "hills": "hill", "mountain": "mountain", "mountains": "mountain", "road": "ground",
    "street": "ground", "sand": "ground", "desert": "ground", "field": "ground", "meadow": "ground",
}
# room nouns: indoor scene, their colour / material words go to the walls
ROOMS = {
    "room": "living", "living": "living", "lounge": "living", "bedroom": "bedroom", "kitchen": "kitchen",
    "office": "office", "study": "office", "library": "library", "bathroom": "bathroom",
    "dining": "dining", "hall": "hall", "hallway": "hall", "corridor": "hall", "museum": "hall",
    "gallery": "hall", "lobby": "hall", "church": "church", "cathedral": "church", "chapel": "church",
    "temple": "church", "interior": "living", "studio": "loft", "loft": "loft", "apartment": "living",
    "attic": "bedroom", "cabin": "living", "classroom": "office", "cafe": "dining", "restaurant": "dining",
    "bar": "dining", "basement": "loft", "garage": "loft", "warehouse": "loft", "indoors": "living",
    "indoor": "living",
}
# room kind -> (floor material word, wall material word, furniture list)
ROOM_KINDS = {
    "living": ("oak", "plaster", ["sofa", "coffee_table", "shelves", "rug", "plant", "painting", "window",
                                  "armchair"]),
    "bedroom": ("wood", "plaster", ["bed", "nightstand", "wardrobe", "rug", "painting", "window", "plant"]),
    "kitchen": ("tiles", "plaster", ["counter", "counter", "table", "chair", "chair", "window"]),
    "office": ("carpet", "plaster", ["desk", "chair", "shelves", "shelves", "plant", "window"]),
    "library": ("parquet", "plaster", ["shelves", "shelves", "shelves", "shelves", "shelves", "table",
                                       "chair", "rug"]),
    "bathroom": ("tiles", "tiles", ["bathtub", "counter", "window", "plant"]),
    "dining": ("parquet", "plaster", ["table", "chair", "chair", "chair", "chair", "cabinet", "painting",
                                      "window"]),
    "hall": ("marble", "plaster", ["painting", "painting", "painting", "bench", "bench", "plant", "window"]),
    "church": ("stone", "stone", ["bench", "bench", "bench", "bench", "window", "window"]),
    "loft": ("concrete", "brick", ["sofa", "table", "shelves", "plant", "window", "window"]),
}
# furniture words that add an object to a room (beyond the room kind's list)
FURNITURE = {
    "sofa": "sofa", "couch": "sofa", "armchair": "armchair", "bed": "bed", "table": "table",
    "desk": "desk", "chair": "chair", "chairs": "chair", "shelf": "shelves", "shelves": "shelves",
    "bookshelf": "shelves", "bookshelves": "shelves", "bookcase": "shelves", "books": "shelves",
    "lamp": "lamp", "lamps": "lamp", "rug": "rug", "plant": "plant", "plants": "plant",
    "painting": "painting", "paintings": "painting", "picture": "painting", "window": "window",
    "windows": "window", "wardrobe": "wardrobe", "cabinet": "cabinet", "bathtub": "bathtub",
    "bench": "bench", "counter": "counter", "piano": "cabinet",
}
SIZES = {"tiny": 0.65, "small": 0.8, "cozy": 0.8, "cosy": 0.8, "narrow": 0.8, "large": 1.5, "big": 1.4,
         "spacious": 1.6, "huge": 2.0, "grand": 2.0, "vast": 2.2}
ROUND = {"round", "circular", "rotunda", "cylindrical"}
LSHAPE = {"l", "lshaped"}

# outdoor biome words -> ground material word (in OUTDOOR_GROUNDS) and what grows there
BIOMES = {
    "forest": "forest", "woods": "forest", "jungle": "forest", "park": "park", "garden": "park",
    "meadow": "park", "field": "park", "fields": "park", "countryside": "park", "valley": "park",
    "beach": "beach", "coast": "beach", "island": "beach", "sea": "beach", "ocean": "beach",
    "desert": "desert", "dunes": "desert", "canyon": "desert", "snow": "snow", "snowy": "snow",
    "winter": "snow", "arctic": "snow", "city": "city", "street": "city", "downtown": "city",
    "town": "village", "village": "village", "mountain": "mountain", "mountains": "mountain",
    "alpine": "mountain", "lake": "lake", "river": "lake", "pond": "lake",
}
OUTDOOR_GROUNDS = {
    "forest": ("grass", (0.05, 0.16, 0.03), (0.12, 0.10, 0.04), 1.0),
    "park": ("grass", (0.08, 0.25, 0.04), (0.16, 0.26, 0.05), 1.0),
    "lake": ("grass", (0.07, 0.22, 0.04), (0.15, 0.22, 0.05), 1.0),
    "beach": ("sand", (0.50, 0.41, 0.27), (0.40, 0.32, 0.20), 1.0),
    "desert": ("sand", (0.55, 0.34, 0.16), (0.44, 0.25, 0.11), 1.5),
    "snow": ("snow", (0.62, 0.64, 0.68), (0.48, 0.52, 0.60), 1.0),
    "city": ("asphalt", (0.09, 0.09, 0.09), (0.16, 0.16, 0.15), 1.0),
    "village": ("grass", (0.10, 0.24, 0.05), (0.25, 0.22, 0.10), 1.0),
    "mountain": ("rock", (0.22, 0.2, 0.17), (0.12, 0.14, 0.06), 2.0),
}

# time of day -> sun elevation (deg), sun radiance, zenith, horizon, ambient
TIMES = {
    "dawn": (4.0, (1.1, 0.55, 0.30), (0.10, 0.14, 0.32), (0.85, 0.48, 0.30), (0.16, 0.14, 0.18)),
    "morning": (22.0, (1.35, 1.20, 0.95), (0.10, 0.26, 0.65), (0.60, 0.66, 0.78), (0.25, 0.28, 0.36)),
    "noon": (62.0, (1.30, 1.24, 1.14), (0.07, 0.22, 0.65), (0.50, 0.64, 0.82), (0.28, 0.33, 0.42)),
    "afternoon": (35.0, (1.45, 1.30, 1.05), (0.08, 0.22, 0.60), (0.62, 0.64, 0.72), (0.26, 0.29, 0.36)),
    "sunset": (3.0, (1.25, 0.50, 0.18), (0.10, 0.10, 0.28), (1.00, 0.42, 0.14), (0.18, 0.13, 0.14)),
    "night": (38.0, (0.10, 0.12, 0.17), (0.003, 0.005, 0.018), (0.015, 0.022, 0.045), (0.025, 0.03, 0.05)),
}
TIME_WORDS = {
    "dawn": "dawn", "sunrise": "dawn", "daybreak": "dawn", "morning": "morning", "noon": "noon",
    "midday": "noon", "day": "noon", "daytime": "noon", "sunny": "noon", "afternoon": "afternoon",
    "sunset": "sunset", "dusk": "sunset", "evening": "sunset", "twilight": "sunset", "night": "night",
    "midnight": "night", "nighttime": "night", "moonlit": "night", "moonlight": "night", "starry": "night",
}
CLOUD_WORDS = {"cloud": 0.45, "clouds": 0.5, "cloudy": 0.6, "overcast": 0.9, "stormy": 0.85}

# effects: each on only when one of its words is in the prompt
FOG_WORDS = {"fog": 1.0, "foggy": 1.0, "mist": 0.6, "misty": 0.6, "haze": 0.4, "hazy": 0.4, "smog": 0.8}
FOG_AMOUNT = {"thick": 2.5, "dense": 2.5, "heavy": 2.0, "light": 0.5, "thin": 0.5}
SHADOW_WORDS = {"shadow", "shadows", "shadowy", "shadowed"}
LIGHT_WORDS = {"lamp", "lamps", "lights", "lit", "candle", "candles", "candlelight", "lantern", "lanterns",
               "chandelier", "lamplight", "streetlights", "streetlamps", "neon", "glowing"}

